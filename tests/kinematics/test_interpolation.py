"""Quintic/min-jerk interpolation, shortest-angle wrapping and spline smoothing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.common.errors import InvalidInputError
from services.kinematics.interpolation import (
    cubic_spline_smooth,
    min_jerk_keypose_trajectory,
    quintic_subdivide,
    smoothstep5,
    wrap_toward,
)
from services.kinematics.robot_models import NOVA5, UR3
from services.kinematics.trajectory import JointLimits, verify_trajectory

LIMITS = JointLimits.from_spec(NOVA5)
NAMES = NOVA5.joint_names


def test_smoothstep_boundary_conditions():
    s, ds, dds = smoothstep5(np.array([0.0, 0.5, 1.0]))
    assert np.allclose(s, [0.0, 0.5, 1.0])
    assert np.allclose(ds[[0, 2]], 0.0) and np.allclose(dds[[0, 2]], 0.0)
    assert ds[1] == pytest.approx(15 / 8)
    tau = np.linspace(0, 1, 1001)
    assert np.all(np.diff(smoothstep5(tau)[0]) >= 0)


@pytest.mark.parametrize("max_step_deg", [1.0, 5.0, 12.0])
def test_quintic_subdivide_respects_max_step(max_step_deg):
    a = np.deg2rad([0, 10, 80, 0, -90, 0])
    b = np.deg2rad([120, -30, 20, 170, 45, -300])
    path = quintic_subdivide(a, b, max_step_deg)
    assert np.array_equal(path[0], a) and np.array_equal(path[-1], b)
    steps = np.max(np.abs(np.diff(path, axis=0)), axis=1)
    assert np.max(steps) <= math.radians(max_step_deg) + 1e-12
    # larger moves get more steps, small first steps (zero velocity at the ends)
    assert steps[0] < steps[len(steps) // 2]
    assert len(quintic_subdivide(a, a + 0.01, max_step_deg)) < len(path)


def test_quintic_subdivide_rejects_bad_input():
    with pytest.raises(InvalidInputError, match="NaN"):
        quintic_subdivide([0, np.nan], [1, 1])
    with pytest.raises(InvalidInputError, match="max_step_deg"):
        quintic_subdivide([0, 0], [1, 1], 0.0)
    with pytest.raises(InvalidInputError, match="goal"):
        quintic_subdivide([0, 0], [1, 1, 1])


def test_wrap_toward_only_where_limits_allow():
    lower = np.array([-2 * np.pi, -np.pi, -2 * np.pi])
    upper = np.array([2 * np.pi, np.pi, 2 * np.pi])
    start = np.deg2rad([170.0, 170.0, 300.0])
    goal = np.deg2rad([-170.0, -170.0, 10.0])
    out = np.rad2deg(wrap_toward(start, goal, lower, upper))
    assert out[0] == pytest.approx(190.0)  # full-turn joint: the short way round
    assert out[1] == pytest.approx(-170.0)  # ±180° joint: 190° is outside its limits
    assert out[2] == pytest.approx(10.0)  # 370° would be nearer but is beyond +360°
    assert np.rad2deg(wrap_toward(start, np.deg2rad([0, 0, -50.0]), lower, upper))[2] == pytest.approx(310.0)


def test_min_jerk_keypose_cycle_with_dwell():
    poses = np.deg2rad(
        [[0, 0, 90, 0, -90, 0], [30, 20, 80, -10, -90, 0], [30, 30, 80, -20, -90, 0], [0, 0, 90, 0, -90, 0]]
    )
    traj = min_jerk_keypose_trajectory(poses, 2.0, 0.5, joint_names=NAMES, limits=LIMITS)
    # move, dwell, move, dwell, move: 3 * 2.0 + 2 * 0.5
    assert traj.duration == pytest.approx(7.0)
    for t, k in ((0.0, 0), (2.0, 1), (2.5, 1), (4.5, 2), (5.0, 2), (7.0, 3)):
        q, qd, qdd = traj.sample(t)
        assert np.allclose(q, poses[k]) and np.allclose(qd, 0) and np.allclose(qdd, 0)
    # the dwell holds the pose exactly
    q_dwell = traj.sample(np.linspace(2.0, 2.5, 11))[0]
    assert np.allclose(q_dwell, poses[1])
    # the move is the quintic smoothstep
    q_mid = traj.sample(1.0)[0]
    assert np.allclose(q_mid, poses[0] + 0.5 * (poses[1] - poses[0]))
    verify_trajectory(traj, LIMITS, start=poses[0], goal=poses[-1])


def test_min_jerk_keypose_stretches_moves_to_the_limits_and_wraps():
    lim = JointLimits.from_spec(UR3)
    poses = np.array([[0, 0, 0, 0, 0, np.deg2rad(170)], [3.0, 0, 0, 0, 0, np.deg2rad(-170)]])
    traj = min_jerk_keypose_trajectory(poses, 0.1, joint_names=UR3.joint_names, limits=lim)
    assert traj.duration > 0.1  # 3 rad in 0.1 s is far beyond 180°/s
    verify_trajectory(traj, lim)
    # joint 6 went the short way (+20°), not 340° back
    assert traj.positions[-1, 5] == pytest.approx(np.deg2rad(190))


def test_cubic_spline_smoothing_passes_through_waypoints():
    w = np.array([[0, 0], [1, 2], [2, 1], [3, 3.0]])
    fine = cubic_spline_smooth(w, samples_per_segment=10)
    assert fine.shape == (31, 2)
    assert np.allclose(fine[::10], w)
    # clamped ends: zero slope at start and end (finite differences on a dense sampling)
    dense = cubic_spline_smooth(w, samples_per_segment=1000)
    assert np.all(np.abs(dense[1] - dense[0]) * 1000 < 0.01)
    assert np.all(np.abs(dense[-1] - dense[-2]) * 1000 < 0.01)
    with pytest.raises(InvalidInputError):
        cubic_spline_smooth(w[:1])
