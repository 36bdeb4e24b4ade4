"""The guarded move's stop condition: a force drop along the guard's direction that holds for a few
packets ends the move; a one-packet jolt, a rise, or a drop along another axis does not."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.errors import InvalidInputError
from services.robot.feedback import FeedbackState
from services.robot.guard import GUARD_DEBOUNCE_PACKETS, force_drop_condition
from tests.conftest import HOME

DOWN = [0.0, 0.0, -1.0]
# the wrist carries the rod: its weight pulls along the guard's direction (-z) by ~1 N
CARRYING = np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0])


def _fb(fx: float, fy: float, fz: float) -> FeedbackState:
    z = np.zeros(6)
    return FeedbackState(
        q=HOME.copy(), qd=z, q_target=HOME.copy(), T_base_tool=np.eye(4),
        tcp_force=np.array([fx, fy, fz, 0.0, 0.0, 0.0]), robot_mode=7, current_command_id=0,
        digital_inputs=0, digital_outputs=0, enabled=True, error=False, collision=False, running=True,
        estop=False, timestamp_ms=0, received_ns=0,
    )  # fmt: skip


def test_a_sustained_drop_along_the_guard_fires_on_its_last_debounce_packet():
    fired = force_drop_condition(CARRYING, 0.6, DOWN)
    touching = _fb(0.0, 0.0, -0.2)  # the table takes 0.8 N of the rod's weight
    results = [fired(touching) for _ in range(GUARD_DEBOUNCE_PACKETS)]
    assert results == [False] * (GUARD_DEBOUNCE_PACKETS - 1) + [True]


def test_a_jolt_a_rise_or_a_drop_along_another_axis_does_not_fire():
    fired = force_drop_condition(CARRYING, 0.6, DOWN)
    seq = [_fb(0, 0, -0.2)] * (GUARD_DEBOUNCE_PACKETS - 1) + [_fb(0, 0, -1.0)]  # a jolt, then back
    seq += [_fb(0, 0, -1.6)] * 10  # more weight: a rise along the guard, not a drop
    seq += [_fb(-2.0, 0, -1.0)] * 10  # sideways force
    assert not any(fired(fb) for fb in seq)


@pytest.mark.parametrize(
    ("drop", "direction"),
    [(0.6, [0.0, 0.0, 0.0]), (0.0, DOWN), (float("nan"), DOWN), (0.6, [0.0, float("inf"), 1.0])],
)
def test_a_guard_without_a_direction_or_a_positive_drop_is_refused(drop: float, direction: list[float]):
    with pytest.raises(InvalidInputError):
        force_drop_condition(CARRYING, drop, direction)
