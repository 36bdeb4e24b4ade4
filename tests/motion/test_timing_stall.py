"""A blended run whose TOPP-RA timing crept over the last tenth of a degree for 9.6 s (seed 1068 of the
eval, the joined path from LIFT to above the place): timed again on a denser grid, it takes what it
should."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import toppra

from services.kinematics.interpolation import arc_lengths
from services.kinematics.robot_models import NOVA5
from services.kinematics.trajectory import JointLimits
from services.motion.timing import _ConstAccelProfile, _stalls, _toppra_profile, time_parameterize

DATA = Path(__file__).parent / "data" / "stalling_blend.npz"


def _case() -> tuple[np.ndarray, JointLimits]:
    d = np.load(DATA)
    limits = JointLimits(d["lower"], d["upper"], d["max_velocity"], d["max_acceleration"])
    return d["path"], limits


def test_the_recorded_path_stalls_on_its_first_grid():
    path, limits = _case()
    chord = arc_lengths(path)
    spline = toppra.SplineInterpolator(chord / chord[-1], path, bc_type="clamped")
    profile = _ConstAccelProfile(*_toppra_profile(spline, limits, 0.97, 1000))
    assert _stalls(profile) and float(np.max(profile.dt)) > 5.0  # one grid interval: most of 12 s


def test_a_stalled_timing_is_timed_again_and_the_run_takes_seconds_not_a_quarter_minute():
    path, limits = _case()
    traj = time_parameterize(path, limits, list(NOVA5.joint_names), method="toppra")
    assert traj.duration < 3.0  # 14.5 s before
    assert np.allclose(traj.positions[-1], path[-1]) and np.allclose(traj.velocities[-1], 0.0)
    speed = np.max(np.abs(traj.velocities) / limits.max_velocity, axis=1)
    # never creeping for long: the last half second still covers the end of the way down
    assert float(np.max(speed[traj.times > traj.duration - 0.5])) > 0.02
