"""What a cycle executed, as the eval's bound reads it: the plan's joint waypoints, not where the arm
happened to be when a call that flows on returned."""

from __future__ import annotations

import numpy as np

from services.task.ports import GripOutcome, MoveOutcome
from services.task.recording import RecordingRobot
from services.task.states import PickOutcome
from tests.task.fakes import line


class _Arm:
    """Answers each execute with the outcome it is given, in order."""

    def __init__(self, *outcomes: MoveOutcome):
        self.outcomes = list(outcomes)
        self.open = False

    async def execute(self, traj, force_guard_n: float = 0.0, continues: bool = False) -> MoveOutcome:  # type: ignore[no-untyped-def]
        return self.outcomes.pop(0)

    async def gripper(self, close: bool, release: bool = False) -> GripOutcome:
        unchanged = not close and self.open  # as the driver's gripper: open jaws are not opened again
        self.open = not close
        return GripOutcome(closed=close, object_detected=None, unchanged=unchanged)


def _q(*v: float) -> np.ndarray:
    return np.array([*v, 0.0, 0.0, 0.0])


async def test_flowing_moves_record_their_planned_ends_and_a_guarded_stop_where_it_stopped():
    a, b, c, d = _q(0, 0, 0), _q(0.5, 0, 0), _q(0.5, 0.4, 0), _q(0.5, 0.4, -0.3)
    mid_flow = _q(0.31, 0, 0)  # the arm when the flowing move's call returned: on its way to b
    at_c = c + 2e-4  # at rest at c, within the tracking error
    stopped = _q(0.5, 0.4, -0.21)  # the touch-down felt the contact before d
    out = PickOutcome(pick_id="p", task="stand-rod", object_class="rod")
    arm = _Arm(
        MoveOutcome(mid_flow, 0.3),
        MoveOutcome(at_c, 0.5),
        MoveOutcome(stopped, 0.4, stopped_early=True),
        MoveOutcome(a + 1e-4, 0.6),
    )
    robot = RecordingRobot(arm, out)  # type: ignore[arg-type]
    await robot.execute(line(a, b), continues=True)
    await robot.execute(line(b, c))
    await robot.gripper(True)
    await robot.execute(line(at_c, d), 0.6)  # planned from where the arm stood
    await robot.execute(line(stopped, a))
    assert np.allclose(out.executed_waypoints, [a, b, c, stopped, a])
    # the arm flowed through b only: at rest where it set off, at c, where the guard stopped it and home
    assert out.executed_rests == [True, False, True, True, True]
    assert out.gripper_actions == 1 and out.gripper_releases == 0
    await robot.gripper(False, release=True)
    assert out.gripper_actions == 2 and out.gripper_releases == 1
    # the next cycle's open ahead of the grasp finds the jaws open: no action, no actuation time
    g = await robot.gripper(False)
    assert g.unchanged and out.gripper_actions == 2 and out.gripper_releases == 1
    await robot.gripper(True)
    assert out.gripper_actions == 3


async def test_a_paced_touch_down_records_the_pace_it_went_under():
    from services.task.pacing import LINE_PACE, LinePace

    a, b, c = _q(0, 0, 0), _q(0.5, 0, 0), _q(0.5, 0, -0.2)
    stopped = _q(0.5, 0, -0.15)
    out = PickOutcome(pick_id="p", task="stand-rod", object_class="rod")
    arm = _Arm(MoveOutcome(b, 0.5), MoveOutcome(stopped, 0.4, stopped_early=True), MoveOutcome(a, 0.5))
    robot = RecordingRobot(arm, out)  # type: ignore[arg-type]
    pace = LinePace(0.2, 0.025, 0.03, 1.0)
    down = line(b, c)
    down.meta[LINE_PACE] = pace
    up = line(stopped, a)
    up.meta[LINE_PACE] = pace  # unguarded: its pace is no touch-down's
    await robot.execute(line(a, b))
    await robot.execute(down, 0.6)
    await robot.execute(up)
    assert np.allclose(out.executed_waypoints, [a, b, stopped, a])
    assert out.executed_paces == {2: pace}  # at the waypoint where the guarded line ended
