"""Every started cycle leaves a record: the task service publishes a pick's record when its cycle
starts and at each stage it reaches (kept on disk in the cycle journal), then once with its
outcome; a cycle a crash cut is published as interrupted, at the stage it reached, when the task
comes back. Over the scripted fakes, with a bus that records what was published."""

from __future__ import annotations

import asyncio
import types
from pathlib import Path

import numpy as np
import pytest
from pickplace.v1 import task_pb2

from services.common.errors import (
    ControllerError,
    EmergencyStopError,
    ExecutionError,
    RobotCommunicationError,
    SafetyError,
)
from services.common.keys import CellKeys
from services.common.modes import TaskKind
from services.common.settings import Settings
from services.kinematics.trajectory import JointTrajectory
from services.task.cycle import Orchestrator
from services.task.journal import CycleJournal
from services.task.ports import MoveOutcome
from services.task.runner import TaskRunner
from tests.task.fakes import HOME, FakeCell, FakeRobot, FakeVision, Fault, rod_at, seen

RUNNING, SUCCEEDED = task_pb2.PICK_STATUS_RUNNING, task_pb2.PICK_STATUS_SUCCEEDED
FAILED, INTERRUPTED = task_pb2.PICK_STATUS_FAILED, task_pb2.PICK_STATUS_INTERRUPTED


class RecordingBus:
    def __init__(self) -> None:
        self.picks: list[task_pb2.PickEvent] = []
        self.keys: list[str] = []
        self.statuses: list[task_pb2.TaskStatus] = []

    def publish(self, key: str, msg: object) -> None:
        if isinstance(msg, task_pb2.PickEvent):
            self.picks.append(msg)
            self.keys.append(key)
        elif isinstance(msg, task_pb2.TaskStatus):
            self.statuses.append(msg)


class HangingRobot(FakeRobot):
    """The fake robot, but the move labelled ``hang_at`` never ends (its process is about to die)."""

    def __init__(self, hang_at: str):
        super().__init__()
        self.hang_at = hang_at
        self.hung = asyncio.Event()

    async def execute(
        self, traj: JointTrajectory, force_guard_n: float = 0.0, continues: bool = False
    ) -> MoveOutcome:
        if traj.meta.get("label") == self.hang_at:
            self.hung.set()
            await asyncio.Event().wait()
        return await super().execute(traj, force_guard_n, continues)


class LostRobot(FakeRobot):
    """The robot service dies during move ``at``: from then on every call fails as a lost link."""

    def __init__(self, at: int):
        super().__init__(faults={at: Fault(RobotCommunicationError("robot service unavailable"))})

    async def recover(self) -> None:
        if self.moves > 0:
            raise RobotCommunicationError("robot service unavailable")
        await super().recover()


def runner_over(settings: Settings, robot: FakeRobot, journal: Path) -> tuple[TaskRunner, RecordingBus]:
    """A task runner whose orchestrator drives the fakes, publishing to a recording bus."""
    bus = RecordingBus()
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), robot=robot)
    clients = types.SimpleNamespace(vision=cell.vision, grasp=cell.grasp, motion=cell.motion, robot=robot)
    runner = TaskRunner(settings, clients, bus, journal=CycleJournal(journal))  # type: ignore[arg-type]
    runner.orchestrator = Orchestrator(
        cell.vision,
        cell.grasp,
        cell.motion,
        robot,
        cell.config,
        on_state=runner._on_state,
        wait=cell.wait,
        clock=lambda: robot.clock_s,
    )
    return runner, bus


@pytest.fixture
def task_settings(settings: Settings) -> Settings:
    return settings.model_copy(update={"task": settings.task.model_copy(update={"park_out_of_view": False})})


async def test_a_cycle_is_recorded_when_it_starts_at_each_stage_and_once_with_its_outcome(
    task_settings: Settings, tmp_path: Path
) -> None:
    journal = tmp_path / "task" / "cycle.pb"
    runner, bus = runner_over(task_settings, FakeRobot(), journal)
    outcome = await runner.run_cycle(TaskKind.STAND_ROD)
    assert outcome.success
    assert {e.pick_id for e in bus.picks} == {outcome.pick_id}
    assert [e.status for e in bus.picks] == [RUNNING] * (len(bus.picks) - 1) + [SUCCEEDED]
    # the running records on their own key: the outcome is the pick's one event on pick_events
    keys = CellKeys(task_settings.cell_id)
    assert bus.keys == [keys.pick_progress] * (len(bus.picks) - 1) + [keys.pick_events]
    stages = [e.stage_reached for e in bus.picks[:-1]]
    assert stages == ["INIT", "DETECT", "PLAN", "APPROACH", "GRASP", "LIFT", "REORIENT", "PLACE", "RELEASE"]
    assert bus.picks[-1].stage_reached == "DONE" and bus.picks[-1].success
    # the records carry what the cycle knew by then: the rod after PLAN, not before
    assert bus.picks[1].object_id == "" and bus.picks[3].object_class == "rod" and bus.picks[3].object_id
    assert not journal.exists()  # the outcome was reported: nothing in progress


async def test_a_task_that_dies_mid_carry_reports_the_cycle_interrupted_when_it_comes_back(
    task_settings: Settings, tmp_path: Path
) -> None:
    journal = tmp_path / "task" / "cycle.pb"
    first, first_bus = runner_over(task_settings, HangingRobot("REORIENT"), journal)
    cut = asyncio.create_task(first.run_cycle(TaskKind.STAND_ROD))
    try:
        robot = first.clients.robot
        assert isinstance(robot, HangingRobot)
        await asyncio.wait_for(robot.hung.wait(), 10.0)
        cut_id = first_bus.picks[0].pick_id
        assert first_bus.picks[-1].stage_reached == "REORIENT" and journal.exists()

        # the process is gone (its cycle never ends); a new one starts on the same state directory
        again, bus = runner_over(task_settings, FakeRobot(), journal)
        found = again.recover_records()
        assert found is not None and bus.picks == [found]
        assert (found.pick_id, found.status, found.stage_reached) == (cut_id, INTERRUPTED, "REORIENT")
        assert found.error_code == "CycleInterruptedError" and not found.success
        assert found.failure_reason == "REORIENT: interrupted: the task process ended"
        assert found.object_class == "rod"  # what the cut cycle had found is kept

        # the next cycle says it once more (nobody may have heard it at start), then records itself
        outcome = await again.run_cycle(TaskKind.STAND_ROD)
        assert outcome.success and outcome.pick_id != cut_id
        assert [(e.pick_id, e.status) for e in bus.picks[:3]] == [
            (cut_id, INTERRUPTED),
            (cut_id, INTERRUPTED),
            (outcome.pick_id, RUNNING),
        ]
        assert bus.picks[-1].status == SUCCEEDED and not journal.exists()
        assert again.recover_records() is None  # reported: a later start finds nothing
    finally:
        # the operator's stop on a running cycle: it too is recorded as interrupted where it was
        cut.cancel()
        with pytest.raises(asyncio.CancelledError):
            await cut
    last = first_bus.picks[-1]
    assert (last.status, last.stage_reached) == (INTERRUPTED, "REORIENT")
    assert last.failure_reason == "REORIENT: interrupted: stopped (the operator's stop or a shutdown)"


async def test_a_safety_stop_or_a_lost_robot_service_still_leaves_the_cycle_its_outcome(
    task_settings: Settings, tmp_path: Path
) -> None:
    estop = FakeRobot(faults={3: Fault(EmergencyStopError("emergency stop pressed"), safety=True)})
    runner, bus = runner_over(task_settings, estop, tmp_path / "a" / "cycle.pb")
    with pytest.raises(SafetyError):
        await runner.run_cycle(TaskKind.STAND_ROD)
    last = bus.picks[-1]
    assert (last.status, last.error_code, last.stage_reached) == (FAILED, "EmergencyStopError", "REORIENT")
    assert "emergency stop" in last.failure_reason
    assert not (tmp_path / "a" / "cycle.pb").exists()

    runner, bus = runner_over(task_settings, LostRobot(at=2), tmp_path / "b" / "cycle.pb")
    with pytest.raises(RobotCommunicationError):
        await runner.run_cycle(TaskKind.STAND_ROD)
    last = bus.picks[-1]
    assert (last.status, last.error_code, last.stage_reached) == (FAILED, "RobotCommunicationError", "LIFT")
    assert last.failure_reason.startswith("LIFT: RobotCommunicationError: robot service unavailable")
    assert len({e.pick_id for e in bus.picks}) == 1


async def test_a_fault_on_the_way_home_fails_that_cycle_and_the_next_one_picks(
    task_settings: Settings, tmp_path: Path
) -> None:
    # the arm left away from the safe home; the execution monitor stops it on the way there (a host
    # that fell behind its ServoJ stream): the cycle fails, the loop goes on, the next cycle picks
    watchdog = ExecutionError("ServoJ watchdog: the stream was not fed for 0.280 s; arm stopped")
    robot = FakeRobot(q=HOME + np.array([0.4, 0, 0, 0, 0, 0]), faults={0: Fault(watchdog)})
    runner, bus = runner_over(task_settings, robot, tmp_path / "cycle.pb")
    failed = await runner.run_cycle(TaskKind.STAND_ROD)
    assert not failed.success and failed.error_code == "ExecutionError"
    assert failed.failure_reason.startswith("INIT: ServoJ watchdog")
    assert (bus.picks[-1].status, bus.picks[-1].stage_reached) == (FAILED, "INIT")
    picked = await runner.run_cycle(TaskKind.STAND_ROD)
    assert picked.success and bus.picks[-1].status == SUCCEEDED and picked.pick_id != failed.pick_id


async def test_an_alarm_mid_carry_is_one_cycle_and_one_outcome(
    task_settings: Settings, tmp_path: Path
) -> None:
    robot = FakeRobot(faults={3: Fault(ControllerError("alarm 117"))})  # REORIENT, the rod in the gripper
    runner, bus = runner_over(task_settings, robot, tmp_path / "cycle.pb")
    outcome = await runner.run_cycle(TaskKind.STAND_ROD)
    assert outcome.success and outcome.error_code == "ControllerError"
    assert [e.status for e in bus.picks].count(SUCCEEDED) == 1 and len({e.pick_id for e in bus.picks}) == 1
    stages = [e.stage_reached for e in bus.picks]
    assert "DETECT" not in stages[stages.index("REORIENT") :]  # resumed where it was, not looked again


async def test_a_journal_that_cannot_be_written_never_fails_the_cycle(
    task_settings: Settings, tmp_path: Path
) -> None:
    journal = tmp_path / "cycle.pb"
    journal.mkdir()  # where the file should go, a directory: every write and read fails
    runner, bus = runner_over(task_settings, FakeRobot(), journal)
    assert runner.recover_records() is None
    outcome = await runner.run_cycle(TaskKind.STAND_ROD)
    assert outcome.success and bus.picks[0].status == RUNNING and bus.picks[-1].status == SUCCEEDED


async def test_the_status_says_a_cycle_is_under_way_from_init_until_it_goes_home(
    task_settings: Settings, tmp_path: Path
) -> None:
    runner, bus = runner_over(task_settings, FakeRobot(), tmp_path / "cycle.pb")
    runner.publish_status()
    assert not bus.statuses[-1].cycle_active  # idle before the cycle
    outcome = await runner.run_cycle(TaskKind.STAND_ROD)
    assert outcome.success
    by_state = {(s.state, s.cycle_active) for s in bus.statuses}
    for state in ("INIT", "DETECT", "PLAN", "APPROACH", "GRASP", "PLACE", "RELEASE"):
        assert (state, True) in by_state and (state, False) not in by_state, state
    assert ("DONE", False) in by_state  # the arm only goes home: the cell may idle there
    runner.publish_status()
    assert not bus.statuses[-1].cycle_active
