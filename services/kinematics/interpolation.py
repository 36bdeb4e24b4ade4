"""Joint-space interpolation: quintic smoothstep / minimum-jerk moves, key-pose cycles, spline smoothing,
a polyline's arc lengths and its densification.

Sources: seed 001 §3.4 (quintic smoothstep subdivision with ``max_step_deg``),
seed 003 (minimum-jerk key-pose interpolation with dwell, shortest-angle
wrapping), LLD §10.2 (cubic-spline smoothing). The results are
:class:`~services.kinematics.trajectory.JointTrajectory` values or dense joint paths.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import CubicSpline

from services.common.errors import InvalidInputError
from services.kinematics.trajectory import (
    TWO_PI,
    Array,
    JointLimits,
    JointTrajectory,
    joint_path,
    joint_vector,
)

# Peaks of the normalised quintic smoothstep s(τ) and its derivatives on [0, 1].
SMOOTHSTEP_PEAK_VELOCITY = 15.0 / 8.0  # s'(1/2)
SMOOTHSTEP_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)  # |s''| at τ = 1/2 ± √3/6
SMOOTHSTEP_PEAK_JERK = 60.0  # |s'''| at τ = 0 and 1


def arc_lengths(path: ArrayLike) -> Array:
    """Joint-space arc length at every point of a polyline (0 at the first)."""
    p = np.asarray(path, dtype=float)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def densify(path: ArrayLike, step_rad: float) -> Array:
    """The polyline with points added on its straight segments so that no joint moves more than
    ``step_rad`` between neighbours (its own points kept)."""
    p = np.asarray(path, dtype=float)
    rows = [p[0]]
    for a, b in itertools.pairwise(p):
        n = max(1, math.ceil(float(np.max(np.abs(b - a))) / step_rad))
        rows.extend(a + s * (b - a) for s in np.linspace(0.0, 1.0, n + 1)[1:])
    return np.array(rows)


def smoothstep5(tau: ArrayLike) -> tuple[Array, Array, Array]:
    """s, ds/dτ, d²s/dτ² of the quintic smoothstep 10τ³ − 15τ⁴ + 6τ⁵ (τ clipped to [0, 1])."""
    t = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    s = t**3 * (10 + t * (-15 + 6 * t))
    ds = 30 * t**2 * (1 - t) ** 2
    dds = 60 * t * (1 - t) * (1 - 2 * t)
    return s, ds, dds


def wrap_toward(q_from: ArrayLike, q_to: ArrayLike, lower: ArrayLike, upper: ArrayLike) -> Array:
    """``q_to`` moved by whole turns to the equivalent angle nearest ``q_from`` that is within limits.

    Joints whose range is shorter than a turn keep their value (there is nothing to
    wrap to); a joint whose every equivalent is outside its limits keeps ``q_to`` so
    the limit check downstream reports it.
    """
    a = np.asarray(q_from, dtype=float)
    b = np.asarray(q_to, dtype=float)
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    k0 = np.round((a - b) / TWO_PI)
    best = b.copy()
    best_dist = np.where((b >= lo) & (b <= hi), np.abs(b - a), np.inf)
    for dk in (-1.0, 0.0, 1.0):
        cand = b + TWO_PI * (k0 + dk)
        dist = np.abs(cand - a)
        ok = (cand >= lo - 1e-12) & (cand <= hi + 1e-12) & (dist < best_dist - 1e-12)
        best = np.where(ok, cand, best)
        best_dist = np.where(ok, dist, best_dist)
    return best


def quintic_subdivide(q_start: ArrayLike, q_goal: ArrayLike, max_step_deg: float = 5.0) -> Array:
    """Joint configurations from start to goal along the quintic smoothstep (seed 001 §3.4).

    The number of steps is chosen so that no joint moves more than ``max_step_deg``
    between consecutive configurations (the middle steps are the largest: the
    smoothstep's peak slope is 15/8). Returns (n + 1, dof), first row = start,
    last row = goal exactly.
    """
    a = np.asarray(q_start, dtype=float).reshape(-1)
    b = np.asarray(q_goal, dtype=float).reshape(-1)
    if a.shape != b.shape:
        raise InvalidInputError(f"start has {a.size} joints but goal has {b.size}")
    a = joint_vector(a, a.size, "start")
    b = joint_vector(b, a.size, "goal")
    if not (math.isfinite(max_step_deg) and max_step_deg > 0):
        raise InvalidInputError(f"max_step_deg must be positive, got {max_step_deg}")
    span = float(np.max(np.abs(b - a))) if a.size else 0.0
    max_step = math.radians(max_step_deg)
    n = max(1, math.ceil(SMOOTHSTEP_PEAK_VELOCITY * span / max_step - 1e-12))
    # the bound above is for the continuous slope; check the discrete steps and refine if needed
    while True:
        s, _, _ = smoothstep5(np.linspace(0.0, 1.0, n + 1))
        if span * float(np.max(np.diff(s))) <= max_step + 1e-12:
            break
        n += 1
    path = a + s[:, None] * (b - a)
    path[-1] = b
    return path


def min_jerk_duration(
    delta: ArrayLike, max_velocity: ArrayLike, max_acceleration: ArrayLike, max_jerk: ArrayLike | None = None
) -> float:
    """Shortest duration T of a minimum-jerk move by ``delta`` that keeps every joint within limits."""
    d = np.abs(np.asarray(delta, dtype=float))
    t_v = SMOOTHSTEP_PEAK_VELOCITY * d / np.asarray(max_velocity, dtype=float)
    t_a = np.sqrt(SMOOTHSTEP_PEAK_ACCELERATION * d / np.asarray(max_acceleration, dtype=float))
    t = max(float(np.max(t_v)), float(np.max(t_a)))
    if max_jerk is not None:
        t = max(t, float(np.max(np.cbrt(SMOOTHSTEP_PEAK_JERK * d / np.asarray(max_jerk, dtype=float)))))
    return t


def min_jerk_keypose_trajectory(
    key_poses: ArrayLike,
    move_duration_s: float,
    dwell_s: float = 0.0,
    *,
    joint_names: Sequence[str],
    limits: JointLimits | None = None,
    wrap: bool = True,
    start_with_dwell: bool = False,
) -> JointTrajectory:
    """Seed 003's key-pose cycle: a minimum-jerk move between consecutive key poses, a dwell at each.

    ``key_poses``: (K, dof) joint configurations in rad. Each move lasts
    ``move_duration_s``, stretched where needed so that ``limits`` (velocity,
    acceleration, jerk) hold. With ``wrap`` (and ``limits``, which say where it is
    allowed), each next pose is moved by whole turns to the nearest equivalent on
    joints whose range allows it; without limits the poses are taken as given.
    The dwell holds the pose exactly after each move (and before the first with
    ``start_with_dwell``); the trajectory ends at the last pose at rest.
    """
    dof = len(joint_names)
    poses = joint_path(key_poses, dof, "key poses")
    if not (math.isfinite(move_duration_s) and move_duration_s > 0):
        raise InvalidInputError(f"move_duration_s must be positive, got {move_duration_s}")
    if not (math.isfinite(dwell_s) and dwell_s >= 0):
        raise InvalidInputError(f"dwell_s must be non-negative, got {dwell_s}")
    if limits is not None:
        if limits.dof != dof:
            raise InvalidInputError(f"limits are for {limits.dof} joints, key poses have {dof}")
        for k, pose in enumerate(poses):
            limits.check_positions(pose, f"key pose {k}")
    times = [0.0]
    knots = [poses[0]]
    if start_with_dwell and dwell_s > 0:
        times.append(dwell_s)
        knots.append(poses[0])
    current = poses[0]
    for k in range(1, poses.shape[0]):
        target = poses[k]
        if wrap and limits is not None:
            target = wrap_toward(current, target, limits.lower, limits.upper)
        duration = move_duration_s
        if limits is not None:
            duration = max(
                duration,
                min_jerk_duration(
                    target - current, limits.max_velocity, limits.max_acceleration, limits.max_jerk
                ),
            )
        if np.max(np.abs(target - current)) == 0.0:
            duration = move_duration_s
        times.append(times[-1] + duration)
        knots.append(target)
        if dwell_s > 0 and k < poses.shape[0] - 1:
            times.append(times[-1] + dwell_s)
            knots.append(target)
        current = target
    q = np.array(knots)
    zeros = np.zeros_like(q)
    # zero velocity and acceleration at every knot: each segment is exactly the quintic smoothstep
    return JointTrajectory(tuple(joint_names), np.array(times), q, zeros, zeros.copy())


def quintic_move(
    q_start: ArrayLike,
    q_goal: ArrayLike,
    *,
    joint_names: Sequence[str],
    limits: JointLimits | None = None,
    duration_s: float | None = None,
) -> JointTrajectory:
    """One minimum-jerk move at rest at both ends, as fast as ``limits`` allow (or ``duration_s``)."""
    dof = len(joint_names)
    a = joint_vector(q_start, dof, "start")
    b = joint_vector(q_goal, dof, "goal")
    if duration_s is None:
        if limits is None:
            raise InvalidInputError("quintic_move needs limits or a duration")
        duration_s = max(
            min_jerk_duration(b - a, limits.max_velocity, limits.max_acceleration, limits.max_jerk), 1e-3
        )
    return min_jerk_keypose_trajectory(
        np.vstack([a, b]), duration_s, 0.0, joint_names=joint_names, limits=limits, wrap=False
    )


def cubic_spline_smooth(waypoints: ArrayLike, samples_per_segment: int = 10) -> Array:
    """LLD §10.2: a clamped cubic spline through the waypoints (unit spacing), sampled densely.

    Returns ((N - 1) * samples_per_segment + 1, dof); the waypoints are on the curve.
    """
    w = np.asarray(waypoints, dtype=float)
    if w.ndim != 2 or w.shape[0] < 2:
        raise InvalidInputError(f"cubic spline smoothing needs (N >= 2, dof) waypoints, got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise InvalidInputError("waypoints contain NaN or infinite values")
    if samples_per_segment < 1:
        raise InvalidInputError(f"samples_per_segment must be >= 1, got {samples_per_segment}")
    u = np.arange(w.shape[0], dtype=float)
    spline = CubicSpline(u, w, axis=0, bc_type="clamped")
    fine = np.linspace(0.0, u[-1], (w.shape[0] - 1) * samples_per_segment + 1)
    out = spline(fine)
    out[0], out[-1] = w[0], w[-1]
    return np.asarray(out)
