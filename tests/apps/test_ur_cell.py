"""The cell on a UR: `pickplace eval --robot ur5e` and `up --job keypose` with a UR model.

The slice runs one seeded trial of the whole cell on the simulated UR e-Series (its own process and
loopback address, the MuJoCo UR5e twin behind it), the driver speaking to it through ur_rtde over real
sockets; the rod is judged by the twin's ground truth, read across the simulated controller's pipe."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.apps import evaluation
from services.apps.cell import Cell
from services.apps.evaluation import run_eval
from services.apps.up import SEED_003_CYCLE, ur_keypose_settings
from services.common.settings import load_settings
from services.common.settings.robot import RobotDriverKind
from services.robot.ur.link import URLink
from tests.apps.conftest import cell_settings


def test_a_ur_keypose_job_runs_seed_003s_cycle_on_the_ur_rtde_driver() -> None:
    s = ur_keypose_settings(load_settings("sim", overrides={"robot": {"model": "ur5e"}}))
    seed_003 = load_settings("sim", SEED_003_CYCLE).cycle
    assert s.robot.model == "ur5e" and s.robot.driver is RobotDriverKind.UR_RTDE
    assert s.cycle == seed_003 and s.cycle.dwell_s == 2.0
    assert s.cycle.poses_deg["grasp"] == (28.6479, -45.8366, 45.8366, -89.9544, 0.0, 0.0)
    assert s.gripper.tool_outputs  # the gripper on the flange's tool outputs
    # on a UR5e these joint poses take the tool tip to x = -0.88 m: the cycle's own box allows it
    assert s.robot.workspace.min[0] < -0.88


def test_a_configured_key_pose_cycle_is_kept_on_a_ur() -> None:
    s = ur_keypose_settings(
        load_settings("sim", overrides={"robot": {"model": "ur3"}, "cycle": {"dwell_s": 0.25}})
    )
    assert s.cycle.dwell_s == 0.25 and s.robot.model == "ur3"


@pytest.mark.integration
@pytest.mark.slow
async def test_a_ur5e_cell_stands_the_rod_over_ur_rtde(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cells: list[Cell] = []

    class RecordedCell(Cell):
        async def __aenter__(self) -> Cell:
            cells.append(self)
            return await super().__aenter__()

    monkeypatch.setattr(evaluation, "Cell", RecordedCell)
    s = cell_settings(tmp_path, robot={"model": "ur5e"}, sim={"speed": 3.0})
    report = await run_eval(s, trials=1, seed=0, progress=False, randomize=False)
    (cell,) = cells
    assert cell.ur_sim is not None and cell.sim is None  # the simulated UR, not the Dobot
    assert cell.settings.robot.driver is RobotDriverKind.UR_RTDE
    assert cell.robot is not None and isinstance(cell.robot.driver.client, URLink)
    (r,) = report.results
    assert not r.harness_error, r.harness_error
    # the twin's verdict: the rod stands on the table, upright, at rest, the gripper open and clear
    assert r.success, f"{r.stage_reached}: {r.failure_reason} {r.ground_truth_reasons}"
    assert r.tilt_after_deg is not None and r.tilt_after_deg < 5.0
    # timed on the UR's own clock: every state's controller time adds up to the cycle
    assert r.cycle_time_s > 0
    assert sum(r.stage_durations_s.values()) == pytest.approx(r.cycle_time_s, abs=0.01)
