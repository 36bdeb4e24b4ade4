"""Time parameterisation of joint paths under velocity, acceleration and jerk limits.

- A straight joint move (two configurations): ruckig, time-optimal and jerk-limited,
  phase-synchronised so the joints stay on the straight line in joint space.
- A multi-waypoint path: TOPP-RA (toppra) along a cubic spline through the
  waypoints under velocity/acceleration limits; when jerk limits are given, a
  1-D ruckig filter on the path parameter limits jerk without leaving the path.
- ``rest_to_rest``: ruckig from waypoint to waypoint, stopping at each — exactly on
  the polyline (used when a smooth blend must not leave the checked path).

Every result passes :func:`services.kinematics.trajectory.verify_trajectory` before
it is returned (a known weakness of MoveIt's time parameterisation is that
nobody checks); limits are tightened and the step repeated when it does not.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np
import toppra
import toppra.algorithm as ta_algo
import toppra.constraint as ta_constraint
from numpy.typing import ArrayLike
from ruckig import InputParameter, OutputParameter, Result, Ruckig, RuckigError, Synchronization, Trajectory

from services.common.errors import InvalidInputError, TrajectoryLimitError
from services.kinematics.interpolation import arc_lengths
from services.kinematics.trajectory import (
    Array,
    JointLimits,
    JointTrajectory,
    joint_path,
    joint_vector,
    verify_trajectory,
)

log = logging.getLogger("pickplace.motion.timing")
# toppra logs its numerical failures at WARNING with its own handler (each line came out twice); a
# failure is caught here and falls back to the next safety step or method, so keep its logger quiet
logging.getLogger("toppra").setLevel(logging.ERROR)

DEFAULT_DT = 0.01  # s between knots (the driver resamples at its ServoJ period)
_SAFETY_STEPS = (0.97, 0.9, 0.8, 0.65)
# how closely the arm's velocity at the start of a path timed from motion must point along the path
# (cosine of the angle to the chord over its first two steps)
START_ALIGNMENT = 0.95
# a motion timed from the arm's motion cannot be slowed uniformly (its start speed is given): what
# TOPP-RA's grid leaves over a tightened limit by this share at most is kept as it is
MOVING_START_SLACK = 1e-3
# TOPP-RA's collocation can leave a grid point next to the end of the path at a near-zero path speed
# (inside the clamped spline's last knot interval, where it curves hard): seed 1068 of the eval crept
# 9.6 s over the last 0.1° of a 2.4 s blend, and 1103 and 1197 alike (3 in 200). A grid interval this
# long, and this large a share of the whole, is timed again on a grid half as dense again, and the
# faster timing kept.
STALL_INTERVAL_S = 0.25
STALL_SHARE = 0.25
GRID_MIN_STEP = 1e-9  # path-parameter intervals below this are merged (a knot on a grid point)
# When TOPP-RA finds no timing on the grid with the knots, a uniform grid point this close to a knot or
# a knot's midpoint (a share of the uniform step) gives way to it: the sliver interval the two left
# (1.6e-6 of the path) made TOPP-RA find no timing at all for a plain 11-point tool line, which then
# stopped at every point (eval seed 1197 under load: 7.7 s for a 1.0 s touch-down, the rod leaning 0.01°
# off the quiet run's lean). Only then: the grid decides where TOPP-RA's switches fall, and leaving
# those points out for every path changed whole runs (a way home 1.73 → 2.08 s, slowed then for the
# quintic's peaks).
GRID_KNOT_CLEARANCE = 0.25


def time_grid(duration: float, dt: float) -> Array:
    """Knot times 0, dt, 2dt, …, duration; the last interval is between dt/2 and 1.5 dt."""
    if duration <= 0:
        return np.zeros(1)
    n = max(1, round(duration / dt))
    ts = np.arange(n + 1, dtype=float) * dt
    ts[-1] = duration
    return ts


def _ruckig_input(dof: int, limits: JointLimits, scale: float, dt: float) -> InputParameter:
    inp = InputParameter(dof)
    inp.max_velocity = (limits.max_velocity * scale).tolist()
    inp.max_acceleration = (limits.max_acceleration * scale).tolist()
    if limits.max_jerk is not None:
        inp.max_jerk = (limits.max_jerk * scale).tolist()
    else:
        # no jerk limit: acceleration still ramps, within one knot period, so the knots (and the
        # C2 interpolation between them) represent the motion exactly
        inp.max_jerk = (limits.max_acceleration * scale / dt).tolist()
    return inp


def _switch_times(tr: Trajectory) -> Array:
    """Times where some joint's jerk changes (phase boundaries of every DoF's profile)."""
    out = []
    for profile in tr.profiles[0]:
        offset = float(profile.brake.duration) + float(profile.accel.duration)
        out.append(offset + np.cumsum(np.asarray(profile.t, dtype=float)))
    return np.concatenate(out) if out else np.zeros(0)


def _sample_ruckig(tr: Trajectory, joint_names: Sequence[str], dt: float) -> JointTrajectory:
    """Knots every ``dt`` plus at every phase boundary: between boundaries the profile is an exact
    cubic, which the quintic interpolation of :class:`JointTrajectory` reproduces exactly."""
    duration = float(tr.duration)
    grid = time_grid(duration, dt)
    switches = _switch_times(tr)
    switches = switches[(switches > 0) & (switches < duration)]
    if switches.size:
        # drop grid points crowding a boundary (tiny intervals are numerically poor)
        near = np.min(np.abs(grid[:, None] - switches[None, :]), axis=1) < 0.1 * dt
        near[[0, -1]] = False
        grid = np.union1d(grid[~near], switches)
        keep = np.concatenate([[True], np.diff(grid) > 1e-9])
        grid = grid[keep]
        grid[-1] = duration
    rows = [tr.at_time(float(t)) for t in grid]
    q = np.array([r[0] for r in rows])
    qd = np.array([r[1] for r in rows])
    qdd = np.array([r[2] for r in rows])
    qd[-1] = 0.0
    qdd[-1] = 0.0
    return JointTrajectory(tuple(joint_names), grid, q, qd, qdd)


def ruckig_move(
    q_start: ArrayLike,
    q_goal: ArrayLike,
    limits: JointLimits,
    joint_names: Sequence[str],
    *,
    dt: float = DEFAULT_DT,
    scale: float = 1.0,
) -> JointTrajectory:
    """Rest-to-rest straight joint move, time-optimal under the (scaled) limits."""
    dof = limits.dof
    path = joint_path(np.vstack([np.ravel(q_start), np.ravel(q_goal)]), dof, "start/goal")
    if np.max(np.abs(path[1] - path[0])) < 1e-12:
        return JointTrajectory.hold(joint_names, path[0])
    inp = _ruckig_input(dof, limits, scale, dt)
    inp.current_position = path[0].tolist()
    inp.current_velocity = [0.0] * dof
    inp.current_acceleration = [0.0] * dof
    inp.target_position = path[1].tolist()
    inp.target_velocity = [0.0] * dof
    inp.target_acceleration = [0.0] * dof
    inp.synchronization = Synchronization.Phase
    tr = Trajectory(dof)
    try:
        result = Ruckig(dof).calculate(inp, tr)
    except RuckigError as exc:
        raise TrajectoryLimitError(f"ruckig could not time the move {path[0]} → {path[1]}: {exc}") from exc
    if result not in (Result.Working, Result.Finished):
        raise TrajectoryLimitError(f"ruckig could not time the move {path[0]} → {path[1]}: {result}")
    out = _sample_ruckig(tr, joint_names, dt)
    out.positions[-1] = path[1]
    return out


def rest_to_rest(
    path: ArrayLike,
    limits: JointLimits,
    joint_names: Sequence[str],
    *,
    dt: float = DEFAULT_DT,
    scale: float = 1.0,
) -> JointTrajectory:
    """Straight ruckig moves between consecutive waypoints, at rest at each one."""
    p = joint_path(path, limits.dof, "path")
    traj = JointTrajectory.hold(joint_names, p[0])
    for k in range(1, p.shape[0]):
        if np.max(np.abs(p[k] - p[k - 1])) < 1e-12:
            continue
        traj = traj.append(ruckig_move(p[k - 1], p[k], limits, joint_names, dt=dt, scale=scale))
    return traj


def moving_start(start_velocity: ArrayLike | None, dof: int) -> Array | None:
    """A start velocity as one value per joint, or None when the arm is at rest (none given, or all zero)."""
    if start_velocity is None:
        return None
    v0 = joint_vector(start_velocity, dof, "start velocity")
    return v0 if bool(np.any(v0 != 0.0)) else None


def _dedupe(path: Array) -> Array:
    keep = np.ones(path.shape[0], dtype=bool)
    keep[1:] = np.max(np.abs(np.diff(path, axis=0)), axis=1) > 1e-9
    return path[keep]


def _toppra_profile(
    geometric: object,
    limits: JointLimits,
    scale: float,
    n_grid: int,
    knots: Array | None = None,
    sd_start: float = 0.0,
    velocity_scale: float | None = None,
) -> tuple[Array, Array]:
    """TOPP-RA's maximal path velocity ṡ at grid points of s ∈ [0, 1] under velocity/acceleration limits.

    ``knots``: the path parameters of the spline's waypoints, made grid points together with the middle
    of each interval between them. TOPP-RA holds the limits only at its grid points, and a sharp corner
    of the path between two of them (waypoints closer than the grid, where the path turns back) bent the
    spline beyond any limit unseen: seen 8× the acceleration limit there (seed 1012 of the eval, the way
    down to above the place), and the whole blended run was then slowed threefold to mend it. When
    TOPP-RA finds no timing on that grid, it is asked again with the uniform points that lie a sliver
    from a knot left out (``GRID_KNOT_CLEARANCE``). ``sd_start``: the path velocity it starts at, under ``velocity_scale`` of the velocity limits (default:
    ``scale``)."""
    vlim = limits.max_velocity * (scale if velocity_scale is None else velocity_scale)
    alim = limits.max_acceleration * scale
    constraints = [
        ta_constraint.JointVelocityConstraint(np.column_stack([-vlim, vlim])),
        ta_constraint.JointAccelerationConstraint(np.column_stack([-alim, alim])),
    ]

    def solve(grid: Array) -> tuple[Array, Array]:
        result = ta_algo.TOPPRA(constraints, geometric, gridpoints=grid).compute_parameterization(
            sd_start, 0.0
        )
        sd = np.asarray(result[1], dtype=float)
        if sd.shape != grid.shape or not np.all(np.isfinite(sd)):
            raise TrajectoryLimitError("TOPP-RA found no feasible timing for the path")
        return grid, np.maximum(sd, 0.0)

    uniform = np.linspace(0.0, 1.0, n_grid)
    if knots is None:
        return solve(uniform)
    try:
        return solve(_grid_with_knots(uniform, knots, 0.0))
    except TrajectoryLimitError:
        return solve(_grid_with_knots(uniform, knots, GRID_KNOT_CLEARANCE / (n_grid - 1)))


def _grid_with_knots(uniform: Array, knots: ArrayLike, clearance: float) -> Array:
    """The uniform grid points more than ``clearance`` from every knot and knot midpoint, and those."""
    k = np.asarray(knots, dtype=float)
    fixed = np.unique(np.clip(np.concatenate([[0.0, 1.0], k, 0.5 * (k[:-1] + k[1:])]), 0.0, 1.0))
    at = np.clip(np.searchsorted(fixed, uniform), 1, fixed.size - 1)
    gap = np.minimum(np.abs(uniform - fixed[at - 1]), np.abs(fixed[at] - uniform))
    grid = np.unique(np.concatenate([uniform[gap > clearance], fixed]))
    grid = grid[np.concatenate([[True], np.diff(grid) > GRID_MIN_STEP])]  # points on one another
    grid[-1] = 1.0
    return grid


class _ConstAccelProfile:
    """s(t) with piecewise-constant path acceleration between TOPP-RA grid points."""

    def __init__(self, grid: Array, sd: Array):
        ds = np.diff(grid)
        vsum = sd[:-1] + sd[1:]
        if np.any(vsum <= 0):
            raise TrajectoryLimitError("TOPP-RA profile stalls (zero path velocity inside the path)")
        self.dt = 2.0 * ds / vsum
        self.t = np.concatenate([[0.0], np.cumsum(self.dt)])
        self.s0, self.sd0 = grid[:-1], sd[:-1]
        self.sdd = (sd[1:] ** 2 - sd[:-1] ** 2) / (2.0 * ds)
        self.duration = float(self.t[-1])

    def __call__(self, t: Array) -> tuple[Array, Array, Array]:
        k = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.dt.size - 1)
        tau = np.clip(t - self.t[k], 0.0, self.dt[k])
        return (
            self.s0[k] + self.sd0[k] * tau + 0.5 * self.sdd[k] * tau**2,
            self.sd0[k] + self.sdd[k] * tau,
            self.sdd[k],
        )


def _smooth_profile(
    profile: _ConstAccelProfile, jerk_s: float, dt: float, sd_start: float = 0.0
) -> tuple[Array, Array, Array, Array]:
    """Follow s(t) with a 1-D ruckig filter of path jerk ``jerk_s``, from the path velocity ``sd_start``.

    The motion stays exactly on the path (only its timing lags the reference) and
    ends at s = 1 at rest. Returns (t, s, ṡ, s̈) every ``dt``.
    """
    vmax = max(float(np.max(profile.sd0)), sd_start, 1e-6)
    amax = max(float(np.max(np.abs(profile.sdd))), 1e-6)
    otg = Ruckig(1, dt)
    inp = InputParameter(1)
    out = OutputParameter(1)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [vmax], [amax], [jerk_s]
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [sd_start], [0.0]
    ts = np.arange(1, math.ceil(profile.duration / dt) + 1, dtype=float) * dt
    s_ref, sd_ref, sdd_ref = profile(ts)
    rows = [(0.0, 0.0, sd_start, 0.0)]
    max_steps = ts.size + int(30.0 / dt)
    for step in range(1, max_steps + 1):
        if step >= ts.size:
            inp.target_position, inp.target_velocity, inp.target_acceleration = [1.0], [0.0], [0.0]
        else:
            k = step - 1
            v = min(float(sd_ref[k]), 0.99 * vmax)
            # under a jerk limit a state (v, a) implies a speed of |v| + a²/2j just before or after
            # it; ruckig rejects target states where that exceeds v_max
            a_room = math.sqrt(2.0 * jerk_s * max(0.99 * vmax - abs(v), 0.0))
            a = math.copysign(min(abs(float(sdd_ref[k])), a_room, amax), float(sdd_ref[k]))
            inp.target_position, inp.target_velocity, inp.target_acceleration = [float(s_ref[k])], [v], [a]
        try:
            result = otg.update(inp, out)
        except RuckigError as exc:
            raise TrajectoryLimitError(
                f"jerk-limited path timing failed at t = {step * dt:.3f} s: {exc}"
            ) from exc
        out.pass_to_input(inp)
        rows.append((step * dt, out.new_position[0], out.new_velocity[0], out.new_acceleration[0]))
        if step >= ts.size and result == Result.Finished:
            break
    else:
        raise TrajectoryLimitError("jerk-limited path timing did not reach the end of the path")
    arr = np.array(rows)
    arr[-1, 1:] = (1.0, 0.0, 0.0)
    return arr[:, 0], np.clip(arr[:, 1], 0.0, 1.0), arr[:, 2], arr[:, 3]


def toppra_path(
    path: ArrayLike,
    limits: JointLimits,
    joint_names: Sequence[str],
    *,
    dt: float = DEFAULT_DT,
    scale: float = 1.0,
    start_velocity: Array | None = None,
) -> JointTrajectory:
    """Near time-optimal timing along a cubic spline through ``path`` (TOPP-RA), jerk-limited when the
    limits carry jerk; from rest, or from the joint velocity ``start_velocity`` (the arm in motion at
    the path's start, along it: the spline leaves its first point in that direction).

    The spline's parameter is the normalised chord length, so it passes through
    every waypoint; the caller checks the spline for collisions. Jerk: TOPP-RA's
    bang-bang path acceleration is followed by a 1-D ruckig filter on the path
    parameter (the motion stays exactly on the spline, only its timing changes);
    whatever still exceeds a limit is then removed by slowing the whole motion
    uniformly (velocity ∝ 1/k, acceleration ∝ 1/k², jerk ∝ 1/k³) — from rest only: a motion
    that starts in motion keeps its start velocity, and is refused instead.
    """
    p = _dedupe(joint_path(path, limits.dof, "path"))
    v0 = moving_start(start_velocity, limits.dof)
    moving = v0 is not None
    if p.shape[0] == 1 and not moving:
        return JointTrajectory.hold(joint_names, p[0])
    if p.shape[0] == 2 and not moving:
        return ruckig_move(p[0], p[1], limits, joint_names, dt=dt, scale=scale)
    if moving and p.shape[0] < 3:
        raise TrajectoryLimitError("a motion from the arm's motion needs a path of three points or more")
    chord = arc_lengths(p)
    knots = chord / chord[-1]
    sd_start = 0.0
    v_scale = scale
    bc: object = "clamped"
    if v0 is not None:
        # the spline leaves the start along the arm's velocity, at the chord's own rate (|dq/ds| = the
        # path's length): the path velocity is then |v0| / length
        speed = float(np.linalg.norm(v0))
        ahead = p[min(2, p.shape[0] - 1)] - p[0]
        if float(v0 @ ahead) < START_ALIGNMENT * speed * float(np.linalg.norm(ahead)):
            raise TrajectoryLimitError("the arm's motion at the start of the path is not along it")
        bc = ((1, v0 * (chord[-1] / speed)), (1, np.zeros(limits.dof)))
        sd_start = speed / float(chord[-1])
        # a motion at a tightened limit goes on from one at that limit: its velocity limit is never
        # tightened below the speed it starts at (TOPP-RA finds no timing from outside its limits)
        v_scale = max(scale, min(1.0, float(np.max(np.abs(v0) / limits.max_velocity)) * (1.0 + 1e-6)))
    geometric = toppra.SplineInterpolator(knots, p, bc_type=bc)
    n_grid = min(1000, max(100, 25 * p.shape[0]))
    profile = _ConstAccelProfile(*_toppra_profile(geometric, limits, scale, n_grid, knots, sd_start, v_scale))
    if _stalls(profile):
        denser = _ConstAccelProfile(
            *_toppra_profile(geometric, limits, scale, n_grid + n_grid // 2, knots, sd_start, v_scale)
        )
        log.debug(
            "TOPP-RA crept %.2f s over one grid interval: %.2f s on a denser grid",
            np.max(profile.dt),
            denser.duration,
        )
        profile = min(profile, denser, key=lambda pr: pr.duration)
    if limits.max_jerk is None:
        ts = time_grid(profile.duration, dt)
        s, s_d, s_dd = profile(ts)
        s_dd = np.asarray(s_dd) * np.ones_like(ts)
    else:
        dense = np.linspace(0.0, 1.0, 400)
        dq = np.max(np.abs(np.asarray(geometric(dense, 1))), axis=0)
        jerk_s = float(np.min(limits.max_jerk * scale / np.maximum(dq, 1e-9)))
        ts, s, s_d, s_dd = _smooth_profile(profile, jerk_s, dt, sd_start)
    q = np.asarray(geometric(s))
    q1 = np.asarray(geometric(s, 1))
    q2 = np.asarray(geometric(s, 2))
    qd = q1 * s_d[:, None]
    qdd = q2 * (s_d**2)[:, None] + q1 * s_dd[:, None]
    q[0], q[-1] = p[0], p[-1]
    qd[0] = v0 if v0 is not None else 0.0
    qd[-1] = 0.0
    qdd[-1] = 0.0
    if not moving:
        qdd[0] = 0.0
    traj = JointTrajectory(tuple(joint_names), ts, q, qd, qdd)
    k = _slowdown_factor(traj, limits, scale, v_scale)
    if moving:  # (within the verification's tolerance of a tightened limit: as it is)
        if k > 1.0 + MOVING_START_SLACK:
            raise TrajectoryLimitError(
                f"timed from the arm's motion, the path exceeds the limits {k:.3f}-fold"
            )
        return traj
    return traj.scaled(k) if k > 1.0 else traj


def _stalls(profile: _ConstAccelProfile) -> bool:
    """Whether one grid interval takes a large share of the motion (see ``STALL_INTERVAL_S``)."""
    longest = float(np.max(profile.dt))
    return longest > STALL_INTERVAL_S and longest > STALL_SHARE * profile.duration


def _slowdown_factor(
    traj: JointTrajectory, limits: JointLimits, scale: float, velocity_scale: float | None = None
) -> float:
    """Uniform time-scale factor that brings velocity, acceleration and mean jerk within limits.

    Acceleration as :func:`verify_trajectory` judges it: at the knots and as their stream (second
    differences of their positions), which TOPP-RA's profile holds between its grid points only
    roughly (a corner between two of them; scaling for it here once is far cheaper than timing the
    path again at lower limits). Not at the quintic's peaks between knots: where the profile switches
    from full acceleration to full deceleration the quintic overshoots by a third of the switch, and
    slowing each run for that bend no streamed position shows cost 5-17 % of every TOPP-RA run.
    """
    v_scale = scale if velocity_scale is None else velocity_scale
    v = float(np.max(np.abs(traj.velocities) / (limits.max_velocity * v_scale)))
    a_limit = limits.max_acceleration * scale
    a = float(np.max(np.abs(traj.accelerations) / a_limit))
    if len(traj) > 2:
        a = max(a, float(np.max(np.abs(traj.streamed_accelerations()) / a_limit)))
    k = max(1.0, v, math.sqrt(a))
    if limits.max_jerk is not None and len(traj) > 1:
        jerk = np.abs(np.diff(traj.accelerations, axis=0) / np.diff(traj.times)[:, None])
        # mean jerk over a knot interval scales as 1/k³ (the interval grows by k as well)
        k = max(k, float(np.max(jerk / (limits.max_jerk * scale))) ** (1.0 / 3.0))
    return k


def time_parameterize(
    path: ArrayLike,
    limits: JointLimits,
    joint_names: Sequence[str],
    *,
    dt: float = DEFAULT_DT,
    method: str = "auto",
    start_velocity: ArrayLike | None = None,
) -> JointTrajectory:
    """Time a joint path at rest at both ends (or from the joint velocity ``start_velocity``: the arm in
    motion along the path at its start; TOPP-RA only) and verify the result against ``limits``.

    ``method``:
    - ``toppra``: TOPP-RA along a cubic spline through the waypoints (jerk-filtered
      when the limits carry jerk);
    - ``rest_to_rest``: jerk-limited straight moves stopping at each waypoint;
    - ``auto``: a single move → ruckig; without jerk limits → ``toppra`` (``rest_to_rest``
      if the spline cannot be timed within limits, e.g. it overshoots a position limit);
      with jerk limits → the faster of the two (the jerk filter slows TOPP-RA's profile,
      so stopping at a few waypoints can win).

    ``meta["method"]`` names the one used; ``meta["on_polyline"]`` is 1.0 when the motion
    stays on the straight segments between waypoints (else it follows the spline and
    the caller must check that curve). Raises TrajectoryLimitError when no tightened
    retry passes verification.
    """
    if len(joint_names) != limits.dof:
        raise InvalidInputError(f"{len(joint_names)} joint names for {limits.dof} joint limits")
    if not (math.isfinite(dt) and 1e-4 <= dt <= 0.1):
        raise InvalidInputError(f"knot period dt must be within [0.0001, 0.1] s, got {dt}")
    if method not in ("auto", "toppra", "rest_to_rest"):
        raise InvalidInputError(f"unknown timing method {method!r} (auto, toppra, rest_to_rest)")
    p = _dedupe(joint_path(path, limits.dof, "path"))
    for k in range(p.shape[0]):
        limits.check_positions(p[k], f"path point {k}")
    v0 = moving_start(start_velocity, limits.dof)
    if v0 is not None:
        if method not in ("auto", "toppra"):
            raise InvalidInputError(f"a motion that starts in motion is timed by TOPP-RA, not {method}")
        return _timed_verified(p, limits, joint_names, dt, "toppra", v0)
    if p.shape[0] <= 2:
        methods = ["rest_to_rest"]
    elif method == "auto":
        methods = ["toppra", "rest_to_rest"]
    else:
        methods = [method]
    best: JointTrajectory | None = None
    errors: list[str] = []
    for name in methods:
        if best is not None and name == "rest_to_rest" and limits.max_jerk is None:
            break  # without jerk limits TOPP-RA's timing is the faster one: no need to compare
        try:
            traj = _timed_verified(p, limits, joint_names, dt, name)
        except TrajectoryLimitError as exc:
            errors.append(f"{name}: {exc}")
            continue
        if best is None or traj.duration < best.duration:
            best = traj
    if best is None:
        raise TrajectoryLimitError(
            f"no timing of the {p.shape[0]}-point path passes the limit check: {errors}"
        )
    return best


def _timed_verified(
    p: Array,
    limits: JointLimits,
    joint_names: Sequence[str],
    dt: float,
    method: str,
    start_velocity: Array | None = None,
) -> JointTrajectory:
    last_error: TrajectoryLimitError | None = None
    for scale in _SAFETY_STEPS:
        try:
            if method == "rest_to_rest":
                traj = rest_to_rest(p, limits, joint_names, dt=dt, scale=scale)
            else:
                traj = toppra_path(p, limits, joint_names, dt=dt, scale=scale, start_velocity=start_velocity)
            moving = start_velocity is not None
            report = verify_trajectory(traj, limits, start=p[0], goal=p[-1], at_rest=not moving)
            if moving and float(np.max(np.abs(traj.velocities[-1]))) > 1e-6:
                raise TrajectoryLimitError("trajectory does not end at rest")
        except TrajectoryLimitError as exc:
            log.debug("%s timing at %.0f %% of the limits failed: %s", method, scale * 100, exc)
            last_error = exc
            continue
        traj.meta.update(
            method=method,
            on_polyline=1.0 if (method == "rest_to_rest" or p.shape[0] <= 2) else 0.0,
            limit_scale=scale,
            velocity_ratio=report.velocity_ratio,
            acceleration_ratio=report.acceleration_ratio,
            jerk_ratio=report.jerk_ratio,
        )
        return traj
    raise TrajectoryLimitError(str(last_error))
