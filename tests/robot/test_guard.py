"""The guarded move's stop condition: a force drop along the guard's direction that holds for a few
packets ends the move; a one-packet jolt, a rise, or a drop along another axis does not."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.errors import InvalidInputError
from services.robot.feedback import FeedbackState
from services.robot.guard import GUARD_DEBOUNCE_PACKETS, force_drop_condition, speed_up_length
from tests.conftest import HOME

DOWN = [0.0, 0.0, -1.0]
# the wrist carries the rod: its weight pulls along the guard's direction (-z) by ~1 N
CARRYING = np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0])


def _fb(fx: float, fy: float, fz: float, tool_z: float = 0.0) -> FeedbackState:
    z = np.zeros(6)
    T = np.eye(4)
    T[2, 3] = tool_z
    return FeedbackState(
        q=HOME.copy(), qd=z, q_target=HOME.copy(), T_base_tool=T,
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


def test_the_guard_watches_only_once_the_descent_has_stopped_speeding_up():
    """Seed 1575: speeding the carried rod down lightened the wrist by 0.8 N (1.4 N peaks at each ServoJ
    step) and the 0.6 N guard stopped the touch-down 28 mm above the table; the rod, let go, fell over."""
    # a descent of 40 mm: 1 m/s² up to 0.2 m/s over its first 20 mm, then down to rest
    t = np.linspace(0.0, 0.4, 41)
    z = np.where(t <= 0.2, -0.5 * t**2, -0.02 - (0.2 * (t - 0.2) - 0.5 * (t - 0.2) ** 2))
    tool = np.column_stack([np.zeros_like(t), np.zeros_like(t), z])
    arm = speed_up_length(tool, t, DOWN)
    assert 0.019 < arm < 0.0211  # where it reached its top speed
    fired = force_drop_condition(CARRYING, 0.6, DOWN, arm_after_m=arm)
    lighter = [_fb(0.0, 0.0, -0.2, tool_z=-0.001 * k) for k in range(17)]  # speeding up: 0.8 N lighter
    assert not any(fired(fb) for fb in lighter)
    # past the speed-up a touch-down fires as before
    touching = [_fb(0.0, 0.0, -0.2, tool_z=-0.025)] * GUARD_DEBOUNCE_PACKETS
    assert [fired(fb) for fb in touching] == [False] * (GUARD_DEBOUNCE_PACKETS - 1) + [True]
    # without the arming distance the same speed-up reads as a touch-down
    unarmed = force_drop_condition(CARRYING, 0.6, DOWN)
    assert any(unarmed(fb) for fb in lighter)


def test_a_descent_at_constant_speed_is_watched_from_its_first_millimetres():
    t = np.linspace(0.0, 1.0, 101)
    ramp = np.minimum(t / 0.04, 1.0)  # 40 ms to the touch-down speed, then steady
    z = -np.concatenate([[0.0], np.cumsum(0.025 * ramp[1:] * np.diff(t))])
    tool = np.column_stack([np.zeros_like(t), np.zeros_like(t), z])
    assert speed_up_length(tool, t, DOWN) < 0.001


def test_a_descent_slow_from_its_start_is_watched_through_its_gentle_speed_up():
    """Seed 1007: the touch-down taken 10 mm further, time-scaled to 25 mm/s on average, speeds up at
    0.25 m/s² over its first 5 mm (too gentle to lighten the wrist by the guard's 0.6 N); unarmed there it
    pushed the rod 3 mm into the table before the guard fired at 12 N."""
    t = np.linspace(0.0, 0.4, 41)
    z = np.where(t <= 0.2, -0.5 * 0.25 * t**2, -0.005 - (0.05 * (t - 0.2) - 0.5 * 0.25 * (t - 0.2) ** 2))
    tool = np.column_stack([np.zeros_like(t), np.zeros_like(t), z])
    assert speed_up_length(tool, t, DOWN) == 0.0
    # the same shape four times as fast (4 m/s²): watched only past its speed-up
    fast = speed_up_length(tool, t / 4, DOWN)
    assert 0.0045 < fast < 0.0056
