"""The arm sets off toward the object while its grasp plans (task.set_off_before_planned)."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pytest

from services.common.errors import (
    ContinuationLateError,
    ControllerError,
    EmergencyStopError,
    PathDeviationError,
    PlanningError,
)
from services.common.modes import TaskKind
from services.kinematics.trajectory import JointTrajectory
from services.task.cycle_config import CycleConfig
from services.task.flow_on import pieces
from services.task.moves import joined_at
from services.task.pick_planning import SET_OFF
from services.task.ports import GraspPlan, MoveOutcome, SeenCube
from services.task.recovery import RetryLimits
from services.task.states import CycleState
from tests.task.fakes import (
    HOME,
    FakeCell,
    FakeGrasp,
    FakeRobot,
    FakeVision,
    Fault,
    joints_at,
    line,
    rod_at,
    seen,
)

HEIGHT = 0.1


def _config(home: np.ndarray = HOME) -> CycleConfig:
    return CycleConfig(
        limits=RetryLimits(detect=2, grasp_variants=3, alarms=2, regrasps=1),
        home_joints=tuple(home),
        set_off_height_m=HEIGHT,
    )


async def test_the_arm_sets_off_above_the_rod_and_the_grasp_plans_from_there() -> None:
    rod = rod_at(0.5, 0.1)
    cell = FakeCell(FakeVision(seen(rod)), config=_config())
    outcome = await cell.run(TaskKind.STAND_ROD)
    assert outcome.success
    # the set-off first, no way back to the safe home; it ends on the grasp's approach line, 11 mm above
    # the pre-grasp: the approach starts there, without a move of its own to the pre-grasp
    assert cell.moves()[:2] == [SET_OFF, "GRASP"]
    above = joints_at([0.5, 0.1, 0.011 + HEIGHT])
    assert np.allclose(cell.robot.reached[SET_OFF], above)
    (call,) = cell.grasp.calls
    assert np.allclose(call.q_now, above)  # planned from where the set-off ends
    first = cell.motion.labelled(["PRE_GRASP", "GRASP"])
    assert np.allclose(first.start, above) and np.allclose(first.moves[0].target, above)  # already there
    # the set-off's scene holds the rod itself (the target is no obstacle of the grasp's own moves)
    set_off = cell.motion.labelled([SET_OFF])
    (move,) = set_off.moves
    assert np.allclose(move.target[:3, :3] @ [0.0, 0.0, 1.0], [0.0, 0.0, -1.0])  # the tool straight down
    assert abs(float(move.target[:3, 1] @ rod.axis)) < 1e-9  # the jaws across the rod
    assert any(np.all(b.min <= rod.center) and np.all(rod.center <= b.max) for b in set_off.obstacles)
    assert not any(np.all(b.min <= rod.center) and np.all(rod.center <= b.max) for b in first.obstacles)
    # planning the set-off is PLAN; the arm on its way is APPROACH
    assert cell.states[:4] == [CycleState.INIT, CycleState.DETECT, CycleState.PLAN, CycleState.APPROACH]
    assert cell.messages[3].startswith("set off")


class SlowGrasp(FakeGrasp):
    """A grasp plan that answers only once ``answer`` is set."""

    def __init__(self) -> None:
        super().__init__()
        self.answer = asyncio.Event()

    async def plan_rod(self, *args: Any, **kwargs: Any) -> GraspPlan:
        await self.answer.wait()
        return await super().plan_rod(*args, **kwargs)


async def test_a_plan_not_ready_when_the_arm_arrives_is_what_it_waits_for_in_plan() -> None:
    grasp = SlowGrasp()
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), grasp=grasp, config=_config())
    recorded = cell.orchestrator._on_state
    assert recorded is not None

    def on_state(state: CycleState, message: str) -> None:
        recorded(state, message)
        if state is CycleState.PLAN and message.startswith("above the object"):
            grasp.answer.set()  # the arm has arrived and waits: now the plan comes

    cell.orchestrator._on_state = on_state
    outcome = await asyncio.wait_for(cell.run(TaskKind.STAND_ROD), 60)  # fails rather than hangs
    assert outcome.success
    assert cell.states[:6] == [
        CycleState.INIT,
        CycleState.DETECT,
        CycleState.PLAN,
        CycleState.APPROACH,
        CycleState.PLAN,
        CycleState.APPROACH,
    ]
    assert cell.robot.commands[1] == ("move", SET_OFF, False)  # it had arrived before the plan came


async def test_a_cube_cycle_sets_off_above_the_first_cube() -> None:
    cubes = (SeenCube(np.array([0.4, -0.1, 0.025]), "red"), SeenCube(np.array([0.55, 0.1, 0.025]), "blue"))
    cell = FakeCell(FakeVision(seen(cubes=cubes)), config=_config())
    outcome = await cell.run(TaskKind.SORT_CUBES)
    assert outcome.success and cell.moves()[0] == SET_OFF
    assert np.allclose(cell.robot.reached[SET_OFF], joints_at([0.4, -0.1, 0.025 + HEIGHT]))


async def test_no_set_off_where_the_pose_above_the_object_is_in_another_arm_branch() -> None:
    """The grasp plans in the safe home's branch: an arm that would reach the pose above the object with
    the elbow the other way waits for the plan where it is."""
    home = HOME.copy()
    home[2] = -0.4  # the toy arm's "elbow" (its z) on the other side
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), robot=FakeRobot(q=home.copy()), config=_config(home))
    outcome = await cell.run(TaskKind.STAND_ROD)
    assert outcome.success and SET_OFF not in cell.moves()
    assert np.allclose(cell.grasp.calls[0].q_now, home)


async def test_a_plan_that_fails_while_the_arm_sets_off_is_a_plan_failure_and_the_move_ends_first() -> None:
    failing = FakeGrasp(failures={k: PlanningError(f"option {k} collides") for k in range(4)})
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), grasp=failing, config=_config())
    outcome = await cell.run(TaskKind.STAND_ROD)
    assert not outcome.success and outcome.stage_reached == "PLAN"
    assert outcome.failure_reason.startswith("PLAN: option 2 collides") and len(failing.calls) == 3
    assert cell.moves() == [SET_OFF]  # ended where it was going, nothing after it
    assert np.allclose(cell.robot.q, joints_at([0.5, 0.1, 0.011 + HEIGHT]))


async def test_a_set_off_stopped_by_an_alarm_is_recovered_and_the_pick_goes_on_from_where_the_arm_stands() -> (
    None
):
    robot = FakeRobot(faults={0: Fault(ControllerError("alarm 22: joint 2 following error"))})
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), robot=robot, config=_config())
    outcome = await cell.run(TaskKind.STAND_ROD)
    assert outcome.success and outcome.attempts >= 1
    assert cell.moves()[0] == SET_OFF and "PRE_GRASP" in cell.moves()
    # the pre-grasp move was planned again from where the alarm stopped the arm, half way
    halfway = HOME + 0.5 * (joints_at([0.5, 0.1, 0.011 + HEIGHT]) - HOME)
    assert any(np.allclose(r.start, halfway) and r.labels[0] == "PRE_GRASP" for r in cell.motion.requests)


async def test_a_safety_stop_on_the_way_is_raised_without_waiting_for_the_plan() -> None:
    grasp = SlowGrasp()  # never answers
    robot = FakeRobot(faults={0: Fault(EmergencyStopError("the emergency stop is pressed"), safety=True)})
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), grasp=grasp, robot=robot, config=_config())
    with pytest.raises(EmergencyStopError):
        await asyncio.wait_for(cell.run(TaskKind.STAND_ROD), 60)  # fails rather than hangs
    assert cell.states[-1] is CycleState.ESTOP and not grasp.calls


async def test_the_set_off_aims_above_where_the_first_option_grasps_a_rod() -> None:
    from services.task.ports import Observation, SeenBox

    rod = rod_at(0.5, 0.1)
    # a small box just beside the rod's centre: the open jaws would come down on it there
    box = SeenBox(np.array([0.495, 0.16, 0.0]), np.array([0.505, 0.17, 0.01]))
    cell = FakeCell(FakeVision(Observation(rods=(rod,), obstacles=(box,))), config=_config())
    outcome = await cell.run(TaskKind.STAND_ROD)
    assert outcome.success
    first_offset = cell.grasp.calls[0].grasp_offset_m
    assert first_offset == pytest.approx(0.035)  # the centre is blocked: the nearest clear offset
    (move,) = cell.motion.labelled([SET_OFF]).moves
    assert np.allclose(move.target[:3, 3], [0.5 + first_offset, 0.1, 0.011 + HEIGHT])
    # and so it ends on that grasp's approach line: no move of its own to the pre-grasp
    assert cell.moves()[:2] == [SET_OFF, "GRASP"]


def test_the_pre_grasp_is_where_the_set_off_ends_only_on_the_approach_line() -> None:
    from services.common.modes import GripperCommand, MotionKind
    from services.task.moves import pre_grasp_at
    from tests.task.fakes import _wp, tool_pose_of

    plan = GraspPlan(
        TaskKind.STAND_ROD,
        [
            _wp("PRE_GRASP", MotionKind.JOINT, (0.5, 0.1, 0.10), gripper=GripperCommand.OPEN),
            _wp("GRASP", MotionKind.LINEAR, (0.5, 0.1, 0.02), gripper=GripperCommand.CLOSE),
            _wp("LIFT", MotionKind.LINEAR, (0.5, 0.1, 0.20), holding=True),
        ],
        0.8,
        None,
        np.zeros(3),
    )

    def at(p: tuple[float, float, float], turn_deg: float = 0.0) -> GraspPlan:
        q = joints_at(p)
        T = tool_pose_of(q)
        c, s = np.cos(np.deg2rad(turn_deg)), np.sin(np.deg2rad(turn_deg))
        T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
        return pre_grasp_at(plan, q, T)

    moved = at((0.5, 0.1, 0.105))  # 5 mm above the pre-grasp, on its line down
    assert np.allclose(moved.waypoints[0].joints, joints_at((0.5, 0.1, 0.105)))
    assert np.allclose(moved.waypoints[0].T_base_tool[:3, 3], [0.5, 0.1, 0.105])
    assert moved.waypoints[0].gripper is GripperCommand.OPEN and moved.waypoints[1:] == plan.waypoints[1:]
    assert at((0.5, 0.1, 0.095)).waypoints[0].joints[2] == pytest.approx(0.095)  # 5 mm below it too
    # off the line, turned otherwise, or too far along it: the pre-grasp stays the plan's
    for off in (at((0.501, 0.1, 0.105)), at((0.5, 0.1, 0.105), turn_deg=0.5), at((0.5, 0.1, 0.13))):
        assert off is plan


# --- the set-off flowing on down the grasp line (task.set_off_flows_on) ----------------------------------
@dataclass
class PacedRobot(FakeRobot):
    """The toy arm, each move taking a few turns of the event loop: the grasp plans meanwhile (as on a
    cell, where a piece of the set-off goes out over 0.06 s)."""

    turns: int = 4

    async def execute(
        self, traj: JointTrajectory, force_guard_n: float = 0.0, continues: bool = False
    ) -> MoveOutcome:
        for _ in range(self.turns):
            await asyncio.sleep(0)
        return await super().execute(traj, force_guard_n, continues)


def _flowing() -> CycleConfig:
    return replace(_config(), set_off_flows_on=True, corner_tolerance_m=0.01)


def _set_off_pieces(cell: FakeCell) -> list[JointTrajectory]:
    (req,) = [r for r in cell.motion.requests if r.labels == [SET_OFF]]
    traj = line(
        np.asarray(req.start),
        req.moves[0].target if req.moves[0].target.ndim == 1 else joints_at(req.moves[0].target[:3, 3]),
    )
    return pieces(traj, _flowing().servo_period_s)


async def test_the_set_off_flows_on_down_the_grasp_line_once_the_plan_is_in() -> None:
    rod = rod_at(0.5, 0.1)
    robot = PacedRobot()
    cell = FakeCell(FakeVision(seen(rod)), robot=robot, config=_flowing())
    outcome = await asyncio.wait_for(cell.run(TaskKind.STAND_ROD), 60)
    assert outcome.success
    assert robot.commands[1:3] == [("gripper", "open"), ("move", SET_OFF, False)]  # open before setting off
    # the way on: the rest of the set-off (in its scene, the rod too; its corner may be rounded) and the
    # grasp line, planned from the end of a piece not yet sent, as fast as the arm moves there
    (way,) = [r for r in cell.motion.requests if r.start_velocity is not None]
    assert way.labels == [SET_OFF, "GRASP"]
    rest = way.moves[0]
    assert rest.blend and rest.blend_tolerance_m == pytest.approx(0.01)
    assert np.allclose(rest.target, joints_at([0.5, 0.1, 0.011 + HEIGHT]))
    assert any(np.all(b.min <= rod.center) and np.all(rod.center <= b.max) for b in rest.obstacles)
    parts = _set_off_pieces(cell)
    k = next(i for i, p in enumerate(parts) if np.allclose(p.positions[-1], way.start))
    assert 0 < k < len(parts) - 1 and np.allclose(way.start_velocity, parts[k].velocities[-1])
    assert np.max(np.abs(way.start_velocity)) > 0.0
    # the pieces up to there went out flowing on, then the way on to the grasp: no stop above the rod,
    # no grasp line of its own; the jaws close where the way on ends
    moves = cell.moves()
    assert moves[: k + 2] == [SET_OFF] * (k + 2) and "GRASP" not in moves
    assert robot.continued[: k + 1] == [SET_OFF] * (k + 1)
    close = robot.commands.index(("gripper", "close"))
    assert robot.commands[close - 1] == ("move", SET_OFF, False)
    assert np.allclose(robot.reached[SET_OFF], joints_at(way.moves[1].target[:3, 3]))  # the grasp pose


async def test_a_plan_in_after_the_last_piece_went_out_leaves_the_set_off_to_end_at_rest() -> None:
    grasp = SlowGrasp()
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), grasp=grasp, robot=PacedRobot(), config=_flowing())
    recorded = cell.orchestrator._on_state
    assert recorded is not None

    def on_state(state: CycleState, message: str) -> None:
        recorded(state, message)
        if state is CycleState.PLAN and message.startswith("above the object"):
            grasp.answer.set()

    cell.orchestrator._on_state = on_state
    outcome = await asyncio.wait_for(cell.run(TaskKind.STAND_ROD), 60)
    assert outcome.success
    assert not [r for r in cell.motion.requests if r.start_velocity is not None]
    n = len(_set_off_pieces(cell))
    assert cell.moves()[: n + 1] == [SET_OFF] * n + ["GRASP"]  # the grasp line from rest, as before


class DeviatingRobot(PacedRobot):
    """The fingers meet the rod's edge on the way down of the first way on: pushed off its path."""

    async def execute(
        self, traj: JointTrajectory, force_guard_n: float = 0.0, continues: bool = False
    ) -> MoveOutcome:
        if joined_at(traj) and not getattr(self, "deviated", False):
            self.deviated = True
            self.q = traj.positions[-1] - 0.3 * (traj.positions[-1] - joined_at(traj)[-1])
            self.commands.append(("move", "WAY_ON", False))
            raise PathDeviationError("joint 3 is 2.1° off the path: pushed off it")
        return await super().execute(traj, force_guard_n, continues)


async def test_a_way_on_pushed_off_its_path_on_the_way_down_is_a_failed_grasp_approach() -> None:
    """As the grasp line would: the arm backs off and another grasp is planned, not the cycle ended."""
    robot = DeviatingRobot()
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), robot=robot, config=_flowing())
    outcome = await asyncio.wait_for(cell.run(TaskKind.STAND_ROD), 60)
    assert getattr(robot, "deviated", False)
    assert outcome.success and len(cell.grasp.calls) == 2
    assert cell.moves()[cell.moves().index("WAY_ON") + 1] == "BACK_OFF"


async def test_a_piece_of_the_set_off_too_late_leaves_the_arm_where_it_rests_and_the_pick_goes_on() -> None:
    robot = FakeRobot(faults={2: Fault(ContinuationLateError("the motion it continues has run out"), at=0.0)})
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), robot=robot, config=_flowing())
    outcome = await asyncio.wait_for(cell.run(TaskKind.STAND_ROD), 60)
    assert outcome.success
    parts = _set_off_pieces(cell)
    # the third piece was refused: the arm rests where the second ended, and the move to the pre-grasp
    # is planned from there
    assert cell.moves()[:3] == [SET_OFF] * 3 and cell.moves()[3] == "PRE_GRASP"
    assert any(
        np.allclose(r.start, parts[1].positions[-1]) and r.labels[0] == "PRE_GRASP"
        for r in cell.motion.requests
    )


async def test_a_cube_s_set_off_goes_whole_its_plan_turns_the_jaws_first() -> None:
    """A cube's set-off keeps the jaws as they are (its faces are not known yet): its plan turns them at
    the pre-grasp, so no way on straight down is looked for and the set-off goes in one call."""
    cubes = (SeenCube(np.array([0.62, -0.2, 0.025]), "red"),)  # far enough for a rod's set-off to be cut
    robot = PacedRobot()
    cell = FakeCell(FakeVision(seen(cubes=cubes)), robot=robot, config=_flowing())
    outcome = await asyncio.wait_for(cell.run(TaskKind.SORT_CUBES), 60)
    assert outcome.success
    assert not [r for r in cell.motion.requests if r.start_velocity is not None]
    assert cell.moves()[:3] == [SET_OFF, "PRE_GRASP", "GRASP"] and SET_OFF not in robot.continued
