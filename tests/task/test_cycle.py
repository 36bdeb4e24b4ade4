"""The pick cycle over scripted fakes: states, the one motion request per plan, the robot's commands."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.errors import CollisionError, ContinuationLateError, StartMismatchError
from services.common.modes import GripperCommand, MotionKind, TaskKind
from services.task.ports import SeenCube
from services.task.states import CycleState
from tests.task.fakes import (
    HELD_ROD,
    HOME,
    FakeCell,
    FakeGrasp,
    FakeMotion,
    FakeRobot,
    FakeVision,
    rod_at,
    seen,
)
from tests.task.fakes import joints_at as fake_joints_at

CLOSE, OPEN = GripperCommand.CLOSE, GripperCommand.OPEN

ROD_STATES = [
    CycleState.INIT,
    CycleState.DETECT,
    CycleState.PLAN,
    CycleState.APPROACH,
    CycleState.GRASP,
    CycleState.LIFT,
    CycleState.REORIENT,
    CycleState.PLACE,
    CycleState.RELEASE,
    CycleState.DONE,  # returning to safe home
    CycleState.DONE,  # object placed
]


async def test_a_rod_cycle_runs_every_state_and_sends_the_plan_in_order() -> None:
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))))
    outcome = await cell.run(TaskKind.STAND_ROD)
    assert outcome.success and outcome.stage_reached == "DONE" and outcome.attempts == 1
    assert outcome.task is TaskKind.STAND_ROD and outcome.object_class == "rod"
    assert cell.states == ROD_STATES
    assert cell.robot.commands == [
        ("recover",),
        ("move", "PRE_GRASP", False),
        ("gripper", OPEN),
        ("move", "GRASP", False),
        ("gripper", CLOSE),
        ("move", "LIFT", False),
        ("move", "REORIENT", False),
        ("move", "PLACE", True),  # guarded: touches down before the end of its line
        ("gripper", OPEN),
        ("move", "RETRACT", False),
        ("move", "HOME", False),
    ]
    assert cell.wait.waits == []


async def test_the_plan_is_three_motion_requests_with_each_moves_scene() -> None:
    """One request to the first stop (the arm sets off with it), one from there to the touch-down,
    one from where it touched down to the safe home (the placed rod an obstacle on the way home)."""
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))))
    await cell.run()
    assert len(cell.motion.requests) == 3
    first, rest, after = cell.motion.requests
    # RELEASE does not move (a gripper action where the arm stands): it is not sent
    assert first.labels == ["SAFE_HOME", "PRE_GRASP", "GRASP"]
    assert rest.labels == ["LIFT", "REORIENT", "PLACE"]
    assert after.labels == ["RETRACT", "HOME"]
    assert first.start == tuple(HOME)
    grasp = next(w for w in cell.grasp.plans[0].waypoints if w.name == "GRASP")
    assert np.allclose(rest.start, fake_joints_at(grasp.T_base_tool[:3, 3]))
    by = {m.label: m for m in first.moves + rest.moves}
    assert [by[n].kind for n in ("SAFE_HOME", "PRE_GRASP", "GRASP")] == [
        MotionKind.JOINT,
        MotionKind.JOINT,
        MotionKind.LINEAR,
    ]
    carried = {n for n, m in by.items() if m.held is HELD_ROD}
    assert carried == {"LIFT", "REORIENT", "PLACE"}
    # the held rod may touch the table while lifting off and setting down, nowhere else
    assert {n for n, m in by.items() if m.table_contact} == {"LIFT", "PLACE"}
    assert {n for n, m in by.items() if m.slow} == {"PLACE"}
    # the guarded approach aims past the nominal pose by the overtravel
    place = next(w for w in cell.grasp.plans[0].waypoints if w.name == "PLACE")
    assert by["PLACE"].target[2, 3] == pytest.approx(place.T_base_tool[2, 3] - 0.02)
    # afterwards: from where PLACE touched down (a quarter short of its target), RETRACT and the way home
    assert np.allclose(after.start, cell.robot.reached["PLACE"])
    home = after.moves[1]
    assert home.kind is MotionKind.JOINT and np.allclose(home.target, HOME)
    (placed,) = home.obstacles
    assert after.moves[0].obstacles == ()  # RETRACT leaves the rod from between the jaws
    xy = cell.grasp.plans[0].place_position[:2]
    assert np.all(placed.min[:2] < xy) and np.all(xy < placed.max[:2]) and placed.min[2] == 0.0


async def test_the_arm_stops_only_where_physics_asks() -> None:
    """Blends everywhere but at the jaws closing, the rest before and the guarded touch-down itself,
    and the release; a blended move continues into the next and an open on the way is done first."""
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))))
    cell.motion.blending = True
    outcome = await cell.run()
    assert outcome.success
    by = {m.label: m for r in cell.motion.requests[:2] for m in r.moves}
    assert {n for n, m in by.items() if m.blend} == {"SAFE_HOME", "PRE_GRASP", "LIFT"}
    assert [m.blend for m in cell.motion.requests[2].moves] == [True, False]  # RETRACT flows home
    assert cell.robot.continued == ["PRE_GRASP", "LIFT", "RETRACT"]
    # the corners flowed through may be rounded; RETRACT's too, as the way home after it has the stood
    # rod in its scene (RETRACT itself starts with the rod between the open jaws and has not)
    rounded = {m.label: m.blend_tolerance_m for r in cell.motion.requests for m in r.moves}
    assert {n for n, tol in rounded.items() if tol > 0} == {"SAFE_HOME", "PRE_GRASP", "LIFT", "RETRACT"}
    retract, home = cell.motion.requests[2].moves
    assert retract.obstacles == () and len(home.obstacles) == 1
    assert {tol for tol in rounded.values() if tol > 0} == {cell.config.corner_tolerance_m}
    assert cell.robot.commands[:5] == [
        ("recover",),
        ("gripper", OPEN),  # before setting off: PRE_GRASP is passed in motion
        ("move", "PRE_GRASP", False),
        ("move", "GRASP", False),
        ("gripper", CLOSE),
    ]
    assert cell.robot.commands.count(("gripper", OPEN)) == 2  # and the release
    # only the open that lets go of the set-down rod answers once the jaws are clear of it
    assert cell.robot.releases == [False, False, True]


class _ShortPreGrasp(FakeMotion):
    """The toy arm's motions, the pre-grasp timed 0.2 s: a short move from rest into the grasp line."""

    async def plan_moves(self, start, moves, obstacles):  # type: ignore[no-untyped-def]
        out = await super().plan_moves(start, moves, obstacles)
        return [
            t.scaled(0.2 / t.duration) if t is not None and t.meta["label"] == "PRE_GRASP" else t for t in out
        ]


async def test_a_short_move_from_rest_goes_out_in_one_call_with_the_move_it_flows_into() -> None:
    """Sent on its own, the 0.2 s pre-grasp would leave the driver less in hand than it keeps ahead of a
    call that flows on by the time the grasp line came (the twin's stream then fell behind and resumed
    from rest). One call takes both; the open was done before setting off and is not asked again on the
    way, the state is GRASP from the call on, and the record keeps the pre-grasp as a point flowed through."""
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), motion=_ShortPreGrasp(blending=True))
    outcome = await cell.run()
    assert outcome.success
    assert cell.robot.commands[:4] == [
        ("recover",),
        ("gripper", OPEN),  # before setting off
        ("move", "PRE_GRASP", False),  # and GRASP with it
        ("gripper", CLOSE),
    ]
    assert cell.robot.continued[0] == "LIFT"  # the joined call ends at rest, at the grasp
    (pre_grasp,) = [m for m in cell.motion.requests[0].moves if m.label == "PRE_GRASP"]
    assert outcome.executed_rests[:3] == [True, False, True]
    assert np.allclose(outcome.executed_waypoints[1], pre_grasp.target)  # a joint move
    assert np.allclose(outcome.executed_waypoints[2], cell.robot.reached["PRE_GRASP"])  # the grasp
    assert cell.states[cell.states.index(CycleState.APPROACH) + 1] is CycleState.GRASP


async def test_a_guarded_approach_is_paced_at_the_touch_down_speed() -> None:
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))))
    outcome = await cell.run()
    # REORIENT ends at z 0.30, PLACE aims at 0.12 − 0.02 overtravel: 0.20 m at 0.02 m/s = 10 s,
    # of which the fake arm runs 3/4 before touching down
    assert outcome.stage_durations_s["PLACE"] == pytest.approx(0.75 * 10.0)
    # stage times are on the injected clock (the fake controller's): they add up to the cycle
    assert sum(outcome.stage_durations_s.values()) == pytest.approx(outcome.cycle_time_s)


async def test_a_cube_cycle_targets_the_first_cube_and_sees_the_others_as_obstacles() -> None:
    cubes = (SeenCube(np.array([0.5, 0.1, 0.025]), "red"), SeenCube(np.array([0.4, -0.1, 0.025]), "blue"))
    cell = FakeCell(FakeVision(seen(cubes=cubes)))
    outcome = await cell.run(TaskKind.SORT_CUBES)
    assert outcome.success and outcome.object_class == "cube_red"
    assert cell.grasp.calls[0].target == "cube_red"
    assert CycleState.TRANSPORT in cell.states and CycleState.REORIENT not in cell.states
    (box,) = cell.motion.requests[0].obstacles  # the blue cube, from the table up
    assert box.min[2] == 0.0 and np.allclose((box.min[:2] + box.max[:2]) / 2, [0.4, -0.1])


async def test_a_dropped_cube_is_let_go_only_once_the_jaws_are_read_holding_it() -> None:
    """No touch-down feels a dropped cube arrive: the object sensor is read at the rest above the zone,
    after the way down and before the jaws let go."""
    cubes = (SeenCube(np.array([0.5, 0.1, 0.025]), "red"),)
    cell = FakeCell(FakeVision(seen(cubes=cubes)), grasp=FakeGrasp(cube_drop=True))
    outcome = await cell.run(TaskKind.SORT_CUBES)
    assert outcome.success
    commands = cell.robot.commands
    place = commands.index(("move", "PLACE", False))  # unguarded
    release = commands.index(("gripper", GripperCommand.OPEN), place)
    assert any(place < k <= release for k in cell.robot.holding_reads)
    assert cell.robot.releases[-1]  # the open let go of the cube


async def test_a_dropped_cube_found_gone_above_its_zone_is_not_reported_placed(
    caplog: pytest.LogCaptureFixture,
) -> None:
    cubes = (SeenCube(np.array([0.5, 0.1, 0.025]), "red"),)
    robot = FakeRobot(holding_script=[True, False])  # held after the lift, gone above the zone
    cell = FakeCell(FakeVision(seen(cubes=cubes)), grasp=FakeGrasp(cube_drop=True), robot=robot)
    outcome = await cell.run(TaskKind.SORT_CUBES)
    assert not outcome.success and outcome.error_code == "GraspFailureError"
    assert "grasp verification before the release at RELEASE" in caplog.text
    assert not any(robot.releases)  # the jaws never opened as if letting go of a placed cube


async def test_a_guarded_touch_down_is_not_followed_by_another_read_before_the_release() -> None:
    cubes = (SeenCube(np.array([0.5, 0.1, 0.025]), "red"),)
    cell = FakeCell(FakeVision(seen(cubes=cubes)))  # the touch-down is guarded
    outcome = await cell.run(TaskKind.SORT_CUBES)
    assert outcome.success
    commands = cell.robot.commands
    place = commands.index(("move", "PLACE", True))
    release = commands.index(("gripper", GripperCommand.OPEN), place)
    assert not any(place < k <= release for k in cell.robot.holding_reads)


async def test_a_cube_that_cannot_be_picked_now_waits_and_the_next_one_is_sorted() -> None:
    """Hemmed in by its neighbours, the first cube has no feasible grasp at all (randomized sort-cubes:
    all 32 options refused, 8 times over, then the cycle aborted): the next cube is planned instead, with
    the first one as an obstacle; the first one's turn comes back only after every cube had one."""
    cubes = (SeenCube(np.array([0.5, 0.1, 0.025]), "red"), SeenCube(np.array([0.4, -0.1, 0.025]), "blue"))
    refused = CollisionError("no feasible pick-and-place for the red cube; tried 32 grasp/turn options")
    cell = FakeCell(FakeVision(seen(cubes=cubes)), grasp=FakeGrasp(failures={0: refused}))
    outcome = await cell.run(TaskKind.SORT_CUBES)
    assert outcome.success and outcome.object_class == "cube_blue" and outcome.attempts == 2
    assert [(c.target, c.alternative) for c in cell.grasp.calls] == [("cube_red", 0), ("cube_blue", 0)]
    (box,) = cell.motion.requests[0].obstacles  # now the red cube is in the way
    assert np.allclose((box.min[:2] + box.max[:2]) / 2, [0.5, 0.1])


async def test_the_arm_is_brought_home_first_when_a_cycle_starts_elsewhere() -> None:
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))))
    cell.robot.q = HOME + np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    outcome = await cell.run()
    assert outcome.success
    assert cell.motion.requests[0].labels == ["SAFE_HOME"]
    assert cell.robot.commands[:2] == [("recover",), ("move", "SAFE_HOME", False)]
    # the grasp plan then starts at home: its SAFE_HOME needs no motion
    assert cell.moves()[1] == "PRE_GRASP"


async def test_a_cycle_starting_low_rises_straight_up_before_going_home() -> None:
    # where an aborted cycle left it: the jaws low beside a box nobody has looked at yet
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))))
    cell.robot.q = np.array([0.5, 0.1, 0.05, 0.0, 0.0, 0.0])  # the toy arm's tool at z = 0.05 m
    outcome = await cell.run()
    assert outcome.success
    first = cell.motion.requests[0]
    assert first.labels == ["RISE", "SAFE_HOME"]
    rise = first.moves[0]
    assert rise.kind is MotionKind.LINEAR and rise.blend
    assert np.allclose(rise.target[:3, 3], [0.5, 0.1, cell.orchestrator.config.home_rise_to_m])  # straight up
    assert cell.robot.commands[1:3] == [("move", "RISE", False), ("move", "SAFE_HOME", False)]


@pytest.mark.parametrize(
    ("refusal", "blending"),
    [
        # a trajectory that flows from a motion that has already ended (a step in speed)
        (
            ContinuationLateError("joint 3 would accelerate at 330°/s²: the motion it continues has ended"),
            True,
        ),
        # one that starts away from the measured joints (randomized stand-rod on a busy machine: 1.59° off
        # after a stream resumed from rest); before, the cycle ended
        (StartMismatchError("trajectory starts 1.59° away from the measured joints (tolerance 1.0°)"), False),
    ],
    ids=["late-continuation", "start-mismatch"],
)
async def test_a_refused_trajectory_is_planned_again_from_where_the_arm_rests(
    refusal: Exception, blending: bool
) -> None:
    """The driver refuses the trajectory to GRASP (nothing is sent); the cycle plans that run again from
    where the arm rests and goes on."""
    from tests.task.fakes import Fault

    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))))
    cell.motion.blending = blending
    cell.robot.faults[1] = Fault(refusal, at=0.0)  # GRASP, which follows PRE_GRASP
    planned_before = len(cell.motion.requests)
    outcome = await cell.run()
    assert outcome.success, outcome.failure_reason
    moves = [c for c in cell.robot.commands if c[0] == "move"]
    assert moves[:3] == [("move", "PRE_GRASP", False), ("move", "GRASP", False), ("move", "GRASP", False)]
    assert len(cell.motion.requests) > planned_before + 3  # the plan's three requests and the replan
