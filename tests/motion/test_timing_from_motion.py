"""Timing a path from the arm's motion: the tail of a motion under way replaced by a longer way that
does not stop where the first one did (services.motion.timing, ``start_velocity``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from services.common.errors import InvalidInputError, TrajectoryLimitError
from services.kinematics.interpolation import arc_lengths
from services.kinematics.trajectory import JointLimits, JointTrajectory, verify_trajectory
from services.motion.corners import round_corner, with_corners
from services.motion.timing import time_parameterize

NAMES = tuple(f"j{k}" for k in range(1, 7))
LIMITS = JointLimits(
    lower=np.full(6, -6.0),
    upper=np.full(6, 6.0),
    max_velocity=np.full(6, 2.0),
    max_acceleration=np.full(6, 8.0),
    max_jerk=np.full(6, 80.0),
)
LINE_LIMITS = dataclasses.replace(LIMITS, max_jerk=None)  # as a blend with a tool line is timed
PERIOD = 0.03  # the driver's streaming period
Q0 = np.zeros(6)
Q1 = np.array([1.0, 0.5, -0.3, 0.2, 0.0, 0.1])  # where the first motion stops
Q2 = Q1 + np.array([0.0, 0.2, 0.2, -0.3, 0.0, 0.0])  # where the way on from there ends


def _first() -> JointTrajectory:
    return time_parameterize(np.vstack([Q0, Q1]), LIMITS, NAMES)


def _on(q_cut: np.ndarray) -> np.ndarray:
    """The rest of the first motion's line from ``q_cut``, then the way on, its corner rounded."""
    line = np.linspace(Q1, Q2, 15)
    path = np.vstack([np.linspace(q_cut, Q1, 20), line[1:]])
    corner = round_corner(path, arc_lengths(path), 19, 0.12, 0.04)
    assert corner is not None
    return with_corners(path, [corner])


def _streamed(*trajs: JointTrajectory) -> np.ndarray:
    """What the driver streams of the trajectories one after another: a target every period."""
    rows = [trajs[0].positions[:1]]
    for t in trajs:
        n = round(t.duration / PERIOD)
        assert t.duration == pytest.approx(n * PERIOD, abs=1e-9) or t is trajs[-1]
        rows.append(t.sample(np.minimum(np.arange(1, n + 1) * PERIOD, t.duration), derivatives=0)[0])
    return np.vstack(rows)


def test_the_tail_of_a_motion_is_replaced_by_a_way_on_timed_from_where_it_is() -> None:
    first = _first()
    t_cut = round(0.45 / PERIOD) * PERIOD  # while the arm moves fast
    head = first.window(0.0, t_cut)
    q_cut, v_cut = head.positions[-1], head.velocities[-1]
    assert np.linalg.norm(v_cut) > 1.0

    on = time_parameterize(_on(q_cut), LINE_LIMITS, NAMES, start_velocity=v_cut)

    # it starts exactly where and as fast as the arm moves, and ends at rest at the new goal
    assert np.array_equal(on.positions[0], q_cut) and np.allclose(on.velocities[0], v_cut)
    assert on.starts_in_motion and not on.ends_in_motion
    assert np.allclose(on.positions[-1], Q2)
    verify_trajectory(on, LINE_LIMITS, goal=Q2, at_rest=False)
    # streamed after the head, no step between the two asks for more than the acceleration limit
    stream = _streamed(head, on)
    accel = np.abs(np.diff(stream, 2, axis=0)) / PERIOD**2
    assert float(np.max(accel / LIMITS.max_acceleration)) <= 1.0 + 1e-3
    # and it is faster than stopping where the first motion ends and going on from rest
    from_rest = time_parameterize(np.linspace(Q1, Q2, 15), LINE_LIMITS, NAMES, method="toppra")
    assert t_cut + on.duration < first.duration + from_rest.duration - 0.1


def test_a_motion_at_a_tightened_limit_goes_on_from_its_full_speed() -> None:
    """The first motion cruises at the tightened limit every timing starts from (97 %): the way on is
    not refused for starting at that speed."""
    far = Q0 + np.array([4.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    first = time_parameterize(np.vstack([Q0, far]), LIMITS, NAMES)
    t_cut = round(first.duration / 2 / PERIOD) * PERIOD
    head = first.window(0.0, t_cut)
    assert float(np.max(np.abs(head.velocities[-1]))) == pytest.approx(0.97 * 2.0, rel=1e-3)
    path = np.linspace(head.positions[-1], far, 30)
    on = time_parameterize(path, LINE_LIMITS, NAMES, start_velocity=head.velocities[-1])
    assert np.allclose(on.velocities[0], head.velocities[-1])
    verify_trajectory(on, LINE_LIMITS, goal=far, at_rest=False)


def test_a_start_velocity_off_the_path_or_of_the_wrong_shape_is_refused_by_name() -> None:
    first = _first()
    head = first.window(0.0, 0.45)
    path = _on(head.positions[-1])
    with pytest.raises(TrajectoryLimitError, match="not along it"):
        time_parameterize(path, LINE_LIMITS, NAMES, start_velocity=-head.velocities[-1])
    with pytest.raises(InvalidInputError, match="start velocity"):
        time_parameterize(path, LINE_LIMITS, NAMES, start_velocity=[1.0, 2.0])
    with pytest.raises(InvalidInputError, match="TOPP-RA"):
        time_parameterize(path, LINE_LIMITS, NAMES, start_velocity=head.velocities[-1], method="rest_to_rest")


def test_a_way_on_too_short_to_take_the_arm_s_speed_is_refused_not_slowed() -> None:
    """Stopping within 2 mrad from full speed is beyond the acceleration limit: a motion from rest
    would be slowed uniformly, but one from the arm's motion cannot change its start speed."""
    first = _first()
    head = first.window(0.0, round(0.45 / PERIOD) * PERIOD)
    q, v = head.positions[-1], head.velocities[-1]
    short = np.linspace(q, q + 0.002 * v / np.linalg.norm(v), 5)
    with pytest.raises(TrajectoryLimitError):
        time_parameterize(short, LINE_LIMITS, NAMES, start_velocity=v)


def test_window_keeps_the_motion_between_its_ends() -> None:
    first = _first()
    part = first.window(0.3, 0.6)
    assert part.duration == pytest.approx(0.3)
    q, qd, _ = first.sample(np.array([0.3, 0.6]))
    assert np.allclose(part.positions[[0, -1]], q) and np.allclose(part.velocities[[0, -1]], qd)
    tail = first.window(0.6, first.duration)
    assert np.array_equal(tail.positions[-1], first.positions[-1]) and not tail.ends_in_motion
    with pytest.raises(InvalidInputError, match="window"):
        first.window(0.5, 0.4)
