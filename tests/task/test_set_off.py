"""The arm sets off toward the object while its grasp plans (task.set_off_before_planned)."""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np
import pytest

from services.common.errors import ControllerError, EmergencyStopError, PlanningError
from services.common.modes import TaskKind
from services.task.cycle_config import CycleConfig
from services.task.pick_planning import SET_OFF
from services.task.ports import GraspPlan, SeenCube
from services.task.recovery import RetryLimits
from services.task.states import CycleState
from tests.task.fakes import HOME, FakeCell, FakeGrasp, FakeRobot, FakeVision, Fault, joints_at, rod_at, seen

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
