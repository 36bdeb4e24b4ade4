"""The eval's trial journal: every finished trial on disk as it ends, and a resumed run that takes them
instead of running them again."""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace
from typing import Any

import pytest

from services.apps import evaluation
from services.apps.eval_journal import TrialJournal, journal_path, read_journal
from services.apps.evaluation import EvalReport, TrialResult, _TrialRunner
from services.common.errors import ConfigurationError
from services.task.states import PickOutcome
from tests.apps.test_evaluation_report import trial

HEADER = {"task": "stand-rod", "seed": 10, "trials": 4, "randomized": True, "calibration_error": None}


def _result(seed: int, success: bool = True) -> TrialResult:
    # the report tests' trial, with the nested fields a journal line must carry back too
    return dataclasses.replace(
        trial(seed, success, rod_mass_kg=0.31),
        stage_durations_s={"DETECT": 0.4, "PLAN": 1.2},
        executed_waypoints=[[0.0] * 6, [0.1] * 6],
    )


def test_journal_path_lies_beside_the_report(tmp_path):
    assert journal_path(tmp_path / "stand-rod.json") == tmp_path / "stand-rod.json.trials.jsonl"


def test_each_trial_is_on_disk_when_append_returns_and_reads_back_equal(tmp_path):
    path = tmp_path / "r.json.trials.jsonl"
    journal = TrialJournal.open(path, HEADER, resume=False)
    first, second = _result(10), _result(11, success=False)
    journal.append(first)
    # read while the journal is still open: the interrupted run's state
    assert read_journal(path, HEADER) == [first]
    journal.append(second)
    journal.close()
    assert read_journal(path, HEADER) == [first, second]
    assert json.loads(path.read_text().splitlines()[0]) == {"header": HEADER}


def test_resume_continues_the_journal_and_a_fresh_run_replaces_it(tmp_path):
    path = tmp_path / "j.jsonl"
    journal = TrialJournal.open(path, HEADER, resume=False)
    journal.append(_result(10))
    journal.close()
    resumed = TrialJournal.open(path, HEADER, resume=True)
    assert [r.seed for r in resumed.done] == [10] and set(resumed.done_by_seed()) == {10}
    resumed.append(_result(11))
    resumed.close()
    assert [r.seed for r in read_journal(path, HEADER)] == [10, 11]
    fresh = TrialJournal.open(path, HEADER, resume=False)
    fresh.close()
    assert fresh.done == [] and read_journal(path, HEADER) == []


def test_a_last_line_cut_short_by_the_interruption_is_dropped(tmp_path):
    path = tmp_path / "j.jsonl"
    journal = TrialJournal.open(path, HEADER, resume=False)
    journal.append(_result(10))
    journal.close()
    with path.open("a") as f:
        f.write('{"trial": {"seed": 11, "succ')  # killed mid-write
    assert [r.seed for r in read_journal(path, HEADER)] == [10]


def test_a_bad_line_inside_the_journal_is_an_error_naming_it(tmp_path):
    path = tmp_path / "j.jsonl"
    journal = TrialJournal.open(path, HEADER, resume=False)
    journal.append(_result(10))
    journal.close()
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0], "not json", lines[1]]) + "\n")
    with pytest.raises(ConfigurationError, match=r"j\.jsonl:2: unreadable trial record"):
        read_journal(path, HEADER)


def test_resuming_the_journal_of_another_evaluation_is_refused(tmp_path):
    path = tmp_path / "j.jsonl"
    TrialJournal.open(path, HEADER, resume=False).close()
    with pytest.raises(
        ConfigurationError, match=r"journal of another evaluation \(task: journal 'stand-rod'"
    ):
        TrialJournal.open(path, {**HEADER, "task": "sort-cubes"}, resume=True)
    path.write_text("{}\n")
    with pytest.raises(ConfigurationError, match="not an eval trial journal"):
        read_journal(path, HEADER)


async def test_a_resumed_run_runs_only_the_trials_its_journal_lacks(tmp_path, monkeypatch):
    """run_all over a scripted cell: seeds 10 and 12 are in the journal, 11 and 13 run (scene reset to
    their own seed) and are appended; the report holds all four in seed order."""
    path = tmp_path / "j.jsonl"
    journal = TrialJournal.open(path, HEADER, resume=False)
    journal.append(_result(10))
    journal.append(_result(12, success=False))
    journal.close()
    journal = TrialJournal.open(path, HEADER, resume=True)

    resets: list[int] = []
    cycles = 0
    vision = SimpleNamespace(waited_capture_s=5.0)  # the frames the cycles waited for, summed

    async def run_cycle(task: str) -> PickOutcome:
        nonlocal cycles
        cycles += 1
        vision.waited_capture_s += 0.25 * cycles  # this cycle's camera time
        return PickOutcome(pick_id=f"p{cycles}", task=task, success=True)

    async def reset_scene(seed: int) -> None:
        resets.append(seed)

    async def judge(self: Any, cell: Any, seed: int, outcome: PickOutcome) -> TrialResult:
        return _result(seed)

    monkeypatch.setattr(_TrialRunner, "judge", judge)
    runner = SimpleNamespace(run_cycle=run_cycle, _on_state=lambda s, m: None, orchestrator=SimpleNamespace())
    cell = SimpleNamespace(
        task=SimpleNamespace(runner=runner), truth=SimpleNamespace(), reset_scene=reset_scene, vision=vision
    )
    report = EvalReport(task="stand-rod", trials=4, seed=10)
    trial = _TrialRunner(evaluation.Settings(), "stand-rod", _spec())
    await trial.run_all(cell, report, 4, 10, None, False, journal)  # type: ignore[arg-type]
    journal.close()

    assert cycles == 2 and resets == [11, 13]
    # each trial run now is charged the camera time of its own cycle, not the sum so far
    assert [r.camera_wall_s for r in report.results if r.seed in (11, 13)] == [0.25, 0.5]
    assert [r.seed for r in report.results] == [10, 11, 12, 13] and report.successes == 3
    assert [r.seed for r in read_journal(path, HEADER)] == [10, 12, 11, 13]


def _spec() -> Any:
    from services.kinematics.robot_models import get_robot

    return get_robot("nova5")


def test_the_cli_refuses_resume_without_a_report_and_another_runs_journal(tmp_path):
    from typer.testing import CliRunner

    from services.apps.cli import app

    result = CliRunner().invoke(app, ["eval", "--resume"])
    assert result.exit_code == 2 and "--resume needs --json" in result.output
    report = tmp_path / "r.json"
    TrialJournal.open(journal_path(report), {**HEADER, "task": "sort-cubes"}, resume=False).close()
    result = CliRunner().invoke(app, ["eval", "--seed", "10", "--json", str(report), "--resume"])
    assert result.exit_code == 2 and "journal of another evaluation" in result.output


async def test_an_eval_keeps_its_state_in_a_directory_of_its_own(tmp_path, monkeypatch):
    """Never the cell's state directory (the task's cycle journal), nor another eval's beside it."""
    seen: list[str] = []

    class Stop(Exception):
        pass

    class CellThatRecords:
        def __init__(self, settings: Any, **kwargs: Any) -> None:
            seen.append(str(settings.state.dir))

        async def __aenter__(self) -> None:
            raise Stop

        async def __aexit__(self, *exc: object) -> None:
            return None

    monkeypatch.setattr(evaluation, "Cell", CellThatRecords)
    s = evaluation.Settings().model_copy(
        update={"state": evaluation.Settings().state.model_copy(update={"dir": str(tmp_path)})}
    )
    for _ in range(2):
        with pytest.raises(Stop):
            await evaluation.run_eval(s, 1, 0, progress=False)
    assert len(seen) == 2 and str(tmp_path) not in seen and seen[0] != seen[1]
    assert all("pickplace-eval-" in d for d in seen)
