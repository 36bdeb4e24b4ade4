"""The two-stage pace of a guarded approach."""

from __future__ import annotations

import numpy as np
import pytest

from services.kinematics.trajectory import JointTrajectory
from services.task.pacing import acceleration_ratio, paced_on_line


def _line(n: int = 51, length: float = 0.05, duration: float = 0.5) -> tuple[JointTrajectory, np.ndarray]:
    """A toy straight line whose first joint is the tool's distance (m), at uniform-ish speed."""
    s = np.linspace(0.0, 1.0, n)
    d = length * (3 * s**2 - 2 * s**3)  # rest to rest
    q = np.zeros((n, 2))
    q[:, 0], q[:, 1] = d, 2 * d
    t = s * duration
    qd = np.gradient(q, t, axis=0)
    qd[0] = qd[-1] = 0.0
    return JointTrajectory(("a", "b"), t, q, qd, np.gradient(qd, t, axis=0)), d


def test_fast_above_the_band_slow_through_it_on_the_same_path() -> None:
    traj, d = _line()
    paced = paced_on_line(traj, d, approach_m_s=0.15, touch_m_s=0.025, band_from_m=0.03)
    assert np.allclose(paced.positions, traj.positions)  # the path is the planned one
    speed = np.abs(paced.velocities[:, 0])  # = tool speed on this toy line
    band = d >= 0.03
    assert np.max(speed[band]) <= 0.025 + 1e-9
    assert np.max(speed[~band]) <= 0.15 + 1e-9 and np.max(speed[~band]) > 0.1
    # faster than the whole line at the touch-down speed, slower than its planned timing
    assert traj.duration < paced.duration < 0.05 / 0.025
    assert np.all(paced.velocities[[0, -1]] == 0.0)


def test_the_approach_is_no_faster_than_planned() -> None:
    traj, d = _line(duration=2.0)  # planned peak 0.0375 m/s
    paced = paced_on_line(traj, d, approach_m_s=0.15, touch_m_s=0.025, band_from_m=0.03)
    assert np.max(np.abs(paced.velocities[:, 0])) <= 0.0375 + 1e-6


def test_the_pace_keeps_the_joint_acceleration_limits() -> None:
    # joint b turns 20 rad per metre of tool travel (near a singularity): the tool's 1 m/s² speed-up
    # asks it for ~20 rad/s², which the driver would refuse against a 5 rad/s² limit
    traj, d = _line(duration=1.0)
    traj = JointTrajectory(
        ("a", "b"), traj.times, traj.positions * [1.0, 10.0], traj.velocities, traj.accelerations
    )
    limit = np.array([50.0, 5.0])
    free = paced_on_line(traj, d, approach_m_s=0.15, touch_m_s=0.025, band_from_m=0.03)
    assert acceleration_ratio(free, limit) > 1.5
    kept = paced_on_line(
        traj, d, approach_m_s=0.15, touch_m_s=0.025, band_from_m=0.03, max_joint_acceleration=limit
    )
    assert acceleration_ratio(kept, limit) <= 1.0
    assert np.allclose(kept.positions, traj.positions)  # the same path, only slower changes of speed
    band = d >= 0.03
    assert np.max(np.abs(kept.velocities[band, 0])) <= 0.025 + 1e-9  # never faster through the band
    assert free.duration < kept.duration


def test_a_pace_within_the_limits_is_left_as_it_is() -> None:
    traj, d = _line()
    free = paced_on_line(traj, d, approach_m_s=0.15, touch_m_s=0.025, band_from_m=0.03)
    kept = paced_on_line(
        traj,
        d,
        approach_m_s=0.15,
        touch_m_s=0.025,
        band_from_m=0.03,
        max_joint_acceleration=np.array([1e3, 1e3]),
    )
    assert np.array_equal(kept.times, free.times) and np.array_equal(kept.velocities, free.velocities)


def test_the_least_time_of_a_paced_line_is_its_two_speeds_and_the_changes_between() -> None:
    from services.task.pacing import LinePace

    pace = LinePace(approach_m_s=0.2, touch_m_s=0.025, band_from_m=0.09, accel_m_s2=1.0)
    # 0 → 0.2 m/s over 20 mm (0.2 s), 50.3 mm at 0.2 m/s, down to 0.025 m/s over 19.7 mm by the band
    # (0.175 s), then the band's 10 mm at 0.025 m/s (0.4 s): reached at the touch speed, not stopped
    assert pace.least_s(0.1) == pytest.approx(0.2 + 0.0503125 / 0.2 + 0.175 + 0.4, rel=2e-3)
    # stopped before the band (a table higher than seen): only the way there counts
    assert pace.least_s(0.05) < pace.least_s(0.09) < pace.least_s(0.1)
    # a line slow all the way: up to the touch speed (0.3 mm), then at it
    slow = LinePace(approach_m_s=0.2, touch_m_s=0.025, band_from_m=0.0, accel_m_s2=1.0)
    assert slow.least_s(0.01) == pytest.approx(0.025 + (0.01 - 0.0003125) / 0.025, rel=2e-3)
    assert pace.least_s(0.0) == 0.0 and pace.least_s(float("nan")) == 0.0


def test_a_paced_line_takes_no_less_than_its_least_time() -> None:
    from services.task.pacing import LinePace

    traj, d = _line(n=201, length=0.05, duration=0.2)
    paced = paced_on_line(traj, d, approach_m_s=0.15, touch_m_s=0.025, band_from_m=0.03)
    least = LinePace(0.15, 0.025, 0.03, 1.0).least_s(0.05)
    assert least <= paced.duration <= least * 1.05
