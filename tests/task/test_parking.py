"""After a cycle the arm stays where it leaves the camera's view clear (the camera model decides),
and the next cycle sets off from there; what vision saw of the arm itself is no obstacle."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.modes import GripperCommand, MotionKind, TaskKind
from services.task.moves import WAY_HOME, move_to, placed_box, rounds
from services.task.ports import GraspPlan, PlannedWaypoint, SeenBox
from tests.task.fakes import HOME, FakeCell, FakeView, FakeVision, joints_at, rod_at, seen


async def test_a_retract_that_leaves_the_view_clear_ends_the_cycle_there() -> None:
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), view=FakeView(clear_above_m=0.25))
    outcome = await cell.run()
    assert outcome.success
    assert cell.moves()[-1] == "RETRACT"  # no way home: the retract (0.25 m up) is out of the view
    assert np.allclose(cell.robot.q[:3], [0.45, 0.0, 0.25])


async def test_the_next_cycle_sets_off_from_where_the_arm_parked() -> None:
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), view=FakeView(clear_above_m=0.25))
    await cell.run()
    n = len(cell.motion.requests)
    outcome = await cell.run()
    assert outcome.success
    # neither INIT nor the plan goes to the safe home first: straight to the pre-grasp
    assert cell.motion.requests[n].labels[0] == "PRE_GRASP"
    assert np.allclose(cell.motion.requests[n].start, joints_at((0.45, 0.0, 0.25)))
    assert "SAFE_HOME" not in cell.moves()


async def test_the_way_home_stops_at_the_first_pose_that_leaves_the_view_clear() -> None:
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))), view=FakeView(clear_above_m=0.32))
    outcome = await cell.run()
    assert outcome.success
    home_move = cell.motion.requests[-1].moves[-1]
    assert home_move.label == "HOME"
    # the retract ends 0.25 m up, the safe home is 0.40 m up: half way is the first clear tenth
    assert np.allclose(
        home_move.target, joints_at((0.45, 0.0, 0.25)) + 0.5 * (HOME - joints_at((0.45, 0.0, 0.25)))
    )
    assert not np.allclose(cell.robot.q, HOME)


async def test_without_a_camera_model_the_arm_returns_to_the_safe_home() -> None:
    cell = FakeCell(FakeVision(seen(rod_at(0.5, 0.1))))
    await cell.run()
    assert cell.moves()[-1] == "HOME" and np.allclose(cell.robot.q, HOME)


async def test_a_seen_box_around_the_parked_arm_is_not_an_obstacle() -> None:
    parked = joints_at((0.45, 0.0, 0.25))
    arm_box = SeenBox(
        np.array([0.40, -0.05, 0.0]), np.array([0.50, 0.05, 0.30])
    )  # the arm, down to the table
    wall = SeenBox(np.array([0.20, 0.30, 0.0]), np.array([0.30, 0.40, 0.10]))
    obs = seen(rod_at(0.5, 0.1))
    obs = type(obs)(rods=obs.rods, obstacles=(arm_box, wall))
    cell = FakeCell(FakeVision(obs), view=FakeView(clear_above_m=0.25))
    cell.robot.q = parked.copy()
    outcome = await cell.run()
    assert outcome.success
    (box,) = cell.motion.requests[0].obstacles
    assert np.allclose(box.min, wall.min) and np.allclose(box.max, wall.max)


async def test_a_seen_box_around_the_arm_at_the_safe_home_is_not_an_obstacle() -> None:
    """The safe home is out of the pick zone's view, yet the image edge may catch the arm there."""
    arm_box = SeenBox(HOME[:3] - [0.02, 0.02, HOME[2]], HOME[:3] + 0.02)  # the arm, stood on the table
    wall = SeenBox(np.array([0.20, 0.30, 0.0]), np.array([0.30, 0.40, 0.10]))
    obs = seen(rod_at(0.5, 0.1))
    cell = FakeCell(FakeVision(type(obs)(rods=obs.rods, obstacles=(arm_box, wall))), view=FakeView())
    cell.robot.q = HOME.copy()
    outcome = await cell.run()
    assert outcome.success
    (box,) = cell.motion.requests[0].obstacles
    assert np.allclose(box.min, wall.min) and np.allclose(box.max, wall.max)


class ArmOverTheWall(FakeView):
    """The arm reaches into the wall's seen box (grown by the own-box pad) while the tool is below 0.31 m."""

    def __init__(self, wall: SeenBox) -> None:
        super().__init__(clear_above_m=0.25)
        self.wall = wall

    def holds_arm(self, q: np.ndarray, box_min: np.ndarray, box_max: np.ndarray) -> bool:
        return bool(np.allclose(box_min, self.wall.min) and q[2] < 0.31 - 1e-9)


async def test_the_arm_never_parks_inside_a_box_it_saw_so_the_next_picture_keeps_the_box() -> None:
    """Parked over the wall beside the drop zone, the next picture took the wall for the arm and left it
    out of the plan; the fingers then hit it (sort-cubes). The park pose leaves every seen box too."""
    wall = SeenBox(np.array([0.20, 0.30, 0.0]), np.array([0.30, 0.40, 0.10]))
    obs = seen(rod_at(0.5, 0.1))
    cell = FakeCell(FakeVision(type(obs)(rods=obs.rods, obstacles=(wall,))), view=ArmOverTheWall(wall))
    outcome = await cell.run()
    assert outcome.success
    home_move = cell.motion.requests[-1].moves[-1]
    assert home_move.label == "HOME"  # the retract (0.25 m up) leaves the view clear, but reaches the wall
    end = cell.grasp.plans[0].waypoints[-1].joints
    # the first tenth of the way home that is out of the box: the tool at 0.31 m
    assert np.allclose(home_move.target, end + 0.4 * (HOME - end))
    # and the next cycle plans with the wall still in it
    await cell.run()
    assert any(np.allclose(b.min, wall.min) for b in cell.motion.requests[-1].obstacles)


@pytest.mark.parametrize("rise", [MotionKind.JOINT, MotionKind.LINEAR])
def test_every_move_after_the_release_passes_the_placed_object_as_an_obstacle(rise: MotionKind) -> None:
    """The rise after a rod's retract may go on the joint line home (services.grasp.rod_carry) or as a
    line up: like the way home, it is planned with the stood rod in its scene, so the corner at the
    retract's end may be rounded; the retract out of the jaws around the rod and a joint move carrying
    it are not."""
    T = np.eye(4)

    def wp(name: str, motion: MotionKind, holding: bool = False, gripper: GripperCommand | None = None):  # type: ignore[no-untyped-def]
        return PlannedWaypoint(name, motion, T, np.zeros(6), gripper=gripper, holding=holding)

    plan = GraspPlan(
        TaskKind.STAND_ROD,
        [
            wp("GRASP", MotionKind.LINEAR, gripper=GripperCommand.CLOSE),
            wp("REORIENT", MotionKind.JOINT, holding=True),
            wp("PLACE_ABOVE", MotionKind.JOINT, holding=True),
            wp("RELEASE", MotionKind.HOLD, holding=True, gripper=GripperCommand.OPEN),
            wp("RETRACT", MotionKind.LINEAR),
            wp("RETRACT_UP", rise),
            wp(WAY_HOME, MotionKind.JOINT),
        ],
        0.9,
        None,
        np.array([0.45, 0.0, 0.0]),
    )
    placed = placed_box(plan)
    obstacles = {w.name: move_to(plan, i).obstacles for i, w in enumerate(plan.waypoints) if move_to(plan, i)}  # type: ignore[union-attr]
    assert obstacles["REORIENT"] == obstacles["PLACE_ABOVE"] == obstacles["RETRACT"] == ()
    names = [w.name for w in plan.waypoints]
    assert rounds(plan, names.index("RETRACT")) and not rounds(plan, names.index("RELEASE"))
    for name in ("RETRACT_UP", WAY_HOME):
        (box,) = obstacles[name]
        assert np.array_equal(box.min, placed.min) and np.array_equal(box.max, placed.max)
