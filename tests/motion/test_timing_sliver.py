"""A plain tool line (the rod's touch-down planned again after the straightening turn, eval seed 1197
under load) whose waypoints fell a hair from TOPP-RA's uniform grid points: with each waypoint added
to the grid beside its neighbour, the 1.6e-6 interval between them left TOPP-RA no timing at all, and
the line went at rest from point to point (1.7 s for a 0.3 s motion; 7.7 s once paced). A uniform point
that near a waypoint gives way to it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import toppra

from services.kinematics.interpolation import arc_lengths
from services.kinematics.robot_models import NOVA5
from services.kinematics.trajectory import JointLimits, verify_trajectory
from services.motion.timing import GRID_KNOT_CLEARANCE, _toppra_profile, time_parameterize

DATA = Path(__file__).parent / "data" / "tool_line_sliver_grid.npz"
N_GRID = 275  # what toppra_path takes for an 11-point path


def _case() -> tuple[np.ndarray, JointLimits, np.ndarray]:
    d = np.load(DATA)
    limits = JointLimits(d["lower"], d["upper"], d["max_velocity"], d["max_acceleration"])
    chord = arc_lengths(d["path"])
    return d["path"], limits, chord / chord[-1]


def test_the_recorded_waypoints_fall_a_hair_from_uniform_grid_points():
    _, _, knots = _case()
    uniform = np.linspace(0.0, 1.0, N_GRID)
    nearest = np.min(np.abs(uniform[:, None] - knots[None, 1:-1]), axis=0)
    assert np.min(nearest) < 1e-5  # the case the fix is for (1.6e-6 recorded)


def test_the_grid_keeps_every_waypoint_and_no_sliver_beside_it():
    path, limits, knots = _case()
    spline = toppra.SplineInterpolator(knots, path, bc_type="clamped")
    grid, sd = _toppra_profile(spline, limits, 1.0, N_GRID, knots)
    assert np.all(np.isfinite(sd)) and sd.shape == grid.shape
    assert all(np.min(np.abs(grid - k)) < 1e-12 for k in knots)  # the waypoints are grid points
    assert np.min(np.diff(grid)) >= GRID_KNOT_CLEARANCE / (N_GRID - 1) * (1 - 1e-9)


def test_the_line_is_timed_along_the_spline_not_at_rest_at_every_point():
    path, limits, _ = _case()
    traj = time_parameterize(path, limits, list(NOVA5.joint_names), dt=0.01, method="toppra")
    assert traj.meta["method"] == "toppra"
    assert traj.duration < 0.5  # 0.28 s; at rest at every point it took 1.7 s
    report = verify_trajectory(traj, limits, start=path[0], goal=path[-1])
    assert report.acceleration_ratio <= 1.0 + 1e-6
