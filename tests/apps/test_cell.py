"""The pick cycle end to end in the twin, through every service and real transports
(Zenoh + gRPC + Dobot TCP), judged by the twin's ground truth."""

from __future__ import annotations

import asyncio
import logging

import numpy as np
import pytest
from pickplace.v1 import task_pb2

from services.apps.cell import Cell
from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.modes import TaskKind
from services.sim.twin import ground_truth as gt
from services.task.cycle import Orchestrator
from services.task.ports import Observation, SeenRod
from services.task.runner import cycle_config
from services.task.states import CycleState
from tests.apps.conftest import cell_settings
from tests.conftest import free_port
from tests.task.fakes import FakeVision

pytestmark = [pytest.mark.integration, pytest.mark.slow]


async def test_full_pick_and_stand_through_all_services(task_settings):
    async with Cell(task_settings, seed=3) as cell:
        keys = CellKeys(cell.settings.cell_id)
        zs = cell.settings.zenoh.model_copy(
            update={"listen": [f"tcp/127.0.0.1:{free_port()}"], "connect": cell.settings.zenoh.listen}
        )
        async with Bus(zs) as watcher:
            picks = watcher.subscribe(keys.pick_events, task_pb2.PickEvent)
            statuses = watcher.subscribe(keys.task_status, task_pb2.TaskStatus)
            await asyncio.sleep(0.3)  # let the second session's subscriptions reach the cell
            outcome = await cell.task.runner.run_cycle(TaskKind.STAND_ROD)
            event = await picks.get(timeout_s=5.0)
            seen_states = set()
            while not statuses._queue.empty():
                seen_states.add((await statuses.get(0.1)).state)
            picks.close()
            statuses.close()
        assert outcome.success, outcome.failure_reason
        await asyncio.sleep(1.0)  # let the rod settle, then judge by ground truth
        standing = gt.check_rod_standing(cell.engine)
        assert standing.success, standing.reasons
        assert event.pick_id == outcome.pick_id and event.success and event.object_class == "rod"
        assert {"DETECT", "PLAN", "GRASP", "LIFT", "REORIENT", "PLACE", "RELEASE"} <= set(
            event.stage_durations_s
        )
        assert {"GRASP", "REORIENT", "PLACE", "DONE"} <= seen_states
        # the camera saw the rod where it was: the placed rod is where the plan put it
        rod = gt.object_pose(cell.engine, "rod")
        assert np.linalg.norm(rod[:2, 3] - np.array(outcome.place_pose[:2])) < 0.01


async def test_no_rod_detect_failed_retries_then_abort(tmp_path):
    s = cell_settings(tmp_path, sim={"twin": {"scene": {"rod": False}}}, task={"detect_retries": 2})
    async with Cell(s, seed=5) as cell:
        states = []
        orch = cell.task.runner.orchestrator
        orch._on_state = lambda st, msg: states.append(st)
        q0 = await cell.task.clients.robot.joints()
        before = cell.sim.controller.next_id
        outcome = await orch.run(TaskKind.STAND_ROD)
        assert not outcome.success
        assert outcome.stage_reached == "DETECT" and "no rod detected" in outcome.failure_reason
        assert states.count(CycleState.DETECT_FAILED) == 3 and states.count(CycleState.RETRY) == 2
        assert states[-1] is CycleState.ABORT
        # left safe: nothing was queued on the controller, the arm is where it was, enabled and idle
        assert cell.sim.controller.next_id == before
        assert np.allclose(await cell.task.clients.robot.joints(), q0, atol=1e-4)
        assert cell.sim.controller.mode.name == "ENABLE"


class _FarVision(FakeVision):
    """The real pipeline's answer replaced by a rod 1.5 m away (beyond the Nova5's reach)."""

    async def observe(self) -> Observation:
        return Observation(
            rods=(SeenRod(np.array([1.5, 0.0, 0.011]), np.array([1.0, 0.0, 0.0]), 0.2, 0.022, 0.9),)
        )


async def test_unreachable_rod_is_a_planning_error_and_nothing_moves(task_settings):
    async with Cell(task_settings, seed=3) as cell:
        c = cell.task.clients
        orch = Orchestrator(_FarVision(), c.grasp, c.motion, c.robot, cycle_config(cell.settings))
        before = cell.sim.controller.next_id
        outcome = await orch.run(TaskKind.STAND_ROD)
        assert not outcome.success and outcome.stage_reached == "PLAN"
        assert outcome.error_code == "IKFailureError"
        assert "reach" in outcome.failure_reason and "1.5" in outcome.failure_reason
        assert cell.sim.controller.next_id == before  # no motion command was sent


async def test_slipping_grasp_is_detected_and_regrasped(tmp_path, caplog):
    # a grip too weak (and slippery) to hold the rod: verification after LIFT must catch it, try again
    weak = {"grip_force_n": 1.0, "pad_friction": 0.05, "object_friction": 0.05}
    s = cell_settings(tmp_path, sim={"twin": {"physics": weak}}, task={"regrasps": 1})
    async with Cell(s, seed=3) as cell:
        states = []
        orch = cell.task.runner.orchestrator
        orch._on_state = lambda st, msg: states.append(st)
        with caplog.at_level(logging.WARNING, logger="pickplace.task.cycle"):
            outcome = await orch.run(TaskKind.STAND_ROD)
        assert not outcome.success
        # the first grasp: lifted, verification failed, the cycle backed off and looked again
        assert any(
            "grasp verification after LIFT" in r.getMessage() and r.getMessage().endswith("→ regrasp")
            for r in caplog.records
        ), [r.getMessage() for r in caplog.records]
        first_grasp = states.index(CycleState.GRASP)
        assert CycleState.DETECT in states[first_grasp:]
        # where the dropped rod comes to rest varies from run to run: it is grasped again (and slips
        # again), the fingers meet it off where it was seen (the monitor stops them short of the grasp:
        # another grasp option), or a later plan is refused; the cycle stops with that error
        assert outcome.error_code in (
            "GraspFailureError",
            "PathDeviationError",
            "CollisionError",
            "IKFailureError",
        ), (outcome.error_code, outcome.failure_reason)
        if outcome.error_code == "GraspFailureError":
            assert states.count(CycleState.GRASP) >= 2  # one regrasp allowed: the second slip ends it
        # never carried on to the place with an empty gripper: the check after LIFT reads the sensor as
        # the arm passes the lift's end, while the turn is handed over (the cycle is in REORIENT when it
        # answers); a rod that slips out after it (hanging between the fingers until the turn) is
        # caught before the touch-down
        assert CycleState.RELEASE not in states
        last_grasp = len(states) - 1 - states[::-1].index(CycleState.GRASP)
        if CycleState.REORIENT in states[last_grasp:]:
            assert outcome.error_code == "GraspFailureError"
            assert any(
                "as the arm passed the lift's end" in r.getMessage()
                or "grasp verification before the touch-down" in r.getMessage()
                for r in caplog.records
            ), [r.getMessage() for r in caplog.records]
        assert not gt.robot_touches(cell.engine, "rod") or not cell.engine.gripper_closed


async def test_estop_during_motion_stops_robot_and_task_reports(task_settings):
    async with Cell(task_settings, seed=3) as cell:
        runner = cell.task.runner
        runner.start(cycles=1)
        for _ in range(600):  # wait (bounded) until the arm is moving toward the rod
            if runner.state in (CycleState.APPROACH, CycleState.GRASP):
                break
            await asyncio.sleep(0.05)
        assert runner.state in (CycleState.APPROACH, CycleState.GRASP)
        await runner.emergency_stop()
        assert runner.state is CycleState.ESTOP and not runner.running
        fb1 = await cell.robot.driver.client.next_feedback()
        await asyncio.sleep(0.3)
        fb2 = await cell.robot.driver.client.next_feedback()
        assert fb2.estop and not fb2.enabled
        assert np.allclose(fb1.q, fb2.q, atol=1e-3)  # the arm stays stopped
        assert runner.status().state == "ESTOP" and runner.last_error == "emergency stop"
