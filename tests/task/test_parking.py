"""After a cycle the arm stays where it leaves the camera's view clear (the camera model decides),
and the next cycle sets off from there; what vision saw of the arm itself is no obstacle."""

from __future__ import annotations

import numpy as np

from services.task.ports import SeenBox
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
