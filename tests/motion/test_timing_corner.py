"""A blended run whose path turns back between two of TOPP-RA's grid points (seed 1012 of the eval, the
joined path from LIFT to above the place: the carry's few millimetres and the way down, waypoints closer
than the grid). The spline bent there beyond the acceleration limit, unseen by the grid, and the whole
run was slowed threefold to mend it (7.7 s for a 2.7 s motion). With the waypoints and the middle of
each interval between them on the grid, the corner is timed where it is."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import toppra

from services.kinematics.interpolation import arc_lengths
from services.kinematics.robot_models import NOVA5
from services.kinematics.trajectory import JointLimits
from services.motion.timing import _ConstAccelProfile, _toppra_profile, time_grid, toppra_path

DATA = Path(__file__).parent / "data" / "corner_between_grid_points.npz"


def _case() -> tuple[np.ndarray, JointLimits, float]:
    d = np.load(DATA)
    limits = JointLimits(d["lower"], d["upper"], d["max_velocity"], d["max_acceleration"])
    return d["path"], limits, float(d["scale"])


def _peak_acceleration_ratio(path: np.ndarray, limits: JointLimits, scale: float, knots: bool) -> float:
    """The highest joint acceleration over its limit along TOPP-RA's profile, every 10 ms."""
    chord = arc_lengths(path)
    s = chord / chord[-1]
    spline = toppra.SplineInterpolator(s, path, bc_type="clamped")
    profile = _ConstAccelProfile(*_toppra_profile(spline, limits, scale, 1000, s if knots else None))
    t = time_grid(profile.duration, 0.01)
    p, pd, pdd = profile(t)
    qdd = np.asarray(spline(p, 2)) * (pd**2)[:, None] + np.asarray(spline(p, 1)) * np.asarray(pdd)[:, None]
    return float(np.max(np.abs(qdd) / (limits.max_acceleration * scale)))


def test_on_a_uniform_grid_the_corner_bends_the_spline_far_beyond_the_limit():
    path, limits, scale = _case()
    assert _peak_acceleration_ratio(path, limits, scale, knots=False) > 5.0  # 8.2× recorded


def test_with_the_waypoints_on_the_grid_the_corner_is_held_near_the_limit():
    path, limits, scale = _case()
    assert _peak_acceleration_ratio(path, limits, scale, knots=True) < 1.5


def test_the_run_is_timed_in_seconds_it_needs_not_slowed_threefold():
    path, limits, scale = _case()
    traj = toppra_path(path, limits, list(NOVA5.joint_names), scale=scale)
    assert traj.duration < 3.5  # 7.7 s on the uniform grid
    assert np.allclose(traj.positions[0], path[0]) and np.allclose(traj.positions[-1], path[-1])
    assert np.allclose(traj.velocities[[0, -1]], 0.0)
    # within the limits it was timed for
    assert np.all(np.abs(traj.velocities) <= limits.max_velocity * scale * (1 + 1e-6))
    assert np.all(np.abs(traj.accelerations) <= limits.max_acceleration * scale * (1 + 1e-6))
