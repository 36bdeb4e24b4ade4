"""Lower bounds on how fast the arm can go through a list of joint waypoints at its limits (pure): what
the eval holds a cycle against.

A motion that starts and ends at rest and passes the waypoints in order without stopping between them
is at least as long as each joint alone needs: free of the other joints and of the way between the
waypoints, a joint still has to come to zero speed wherever it turns back, and it goes from turn to turn
no faster than time-optimal jerk-limited (ruckig) moves allow. At a turn its speed is zero but not its
acceleration (it swings through, it does not halt): the least time over the accelerations it may turn
with is found on a grid of them (``TURN_ACCEL_STEPS``). The slowest joint's time is the bound.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike
from ruckig import InputParameter, Result, Ruckig, Trajectory

from services.common.errors import InvalidInputError, TrajectoryLimitError
from services.kinematics.trajectory import JointLimits, joint_path

Array = np.ndarray
STILL_RAD = 1e-9  # a joint that moves less than this between two waypoints stays where it is
# accelerations a joint may turn back with, from -max to +max: the least time over this grid is within
# 0.1 % of the least over all of them (tests/motion/test_bound.py)
TURN_ACCEL_STEPS = 81


def turning_points(x: Array) -> Array:
    """The values of one joint's waypoint sequence ``x`` where it starts, turns back and ends."""
    moved = np.concatenate([[True], np.abs(np.diff(x)) > STILL_RAD])
    v = np.asarray(x, dtype=float)[moved]
    if v.size <= 2:
        return v
    step = np.sign(np.diff(v))
    turns = np.flatnonzero(step[1:] != step[:-1]) + 1
    return np.concatenate([[v[0]], v[turns], [v[-1]]])


def one_joint_move_s(start: float, goal: float, v_max: float, a_max: float, j_max: float | None) -> float:
    """Duration of the time-optimal rest-to-rest move of one joint (ruckig), jerk-limited when
    ``j_max`` is given."""
    if abs(goal - start) <= STILL_RAD:
        return 0.0
    t = _swing_s(start, 0.0, goal, 0.0, v_max, a_max, j_max)
    if not np.isfinite(t):
        raise TrajectoryLimitError(f"ruckig could not time a joint move {start} → {goal}")
    return t


def _swing_s(
    x0: float, a0: float, x1: float, a1: float, v_max: float, a_max: float, j_max: float | None
) -> float:
    """The time-optimal move of one joint (ruckig) from ``x0`` to ``x1``, at zero speed at both ends
    with the accelerations ``a0`` and ``a1`` there, jerk-limited when ``j_max`` is given (inf where
    ruckig finds none)."""
    inp = InputParameter(1)
    inp.current_position, inp.target_position = [x0], [x1]
    inp.current_velocity = inp.target_velocity = [0.0]
    inp.current_acceleration, inp.target_acceleration = [a0], [a1]
    inp.max_velocity, inp.max_acceleration = [v_max], [a_max]
    if j_max is not None:
        inp.max_jerk = [j_max]
    tr = Trajectory(1)
    if Ruckig(1).calculate(inp, tr) not in (Result.Working, Result.Finished):
        return float("inf")
    return float(tr.duration)


def through_turns_s(turns: Array, v_max: float, a_max: float, j_max: float | None) -> float:
    """The least duration of one joint from rest at ``turns[0]`` through the turns between (zero speed,
    any acceleration within ``a_max``) to rest at ``turns[-1]``. Without a jerk limit the acceleration may
    jump at a turn: the rest-to-rest moves between turns add up. With one, the turns' accelerations are
    chosen on a grid (``TURN_ACCEL_STEPS``), turn by turn (dynamic programming)."""
    x = [float(v) for v in turns]
    if len(x) < 2:
        return 0.0
    if j_max is None or len(x) == 2:
        return sum(one_joint_move_s(x0, x1, v_max, a_max, j_max) for x0, x1 in pairwise(x))
    grid = np.linspace(-a_max, a_max, TURN_ACCEL_STEPS)
    best = {0.0: 0.0}  # the acceleration at the current turn → the least time to get there with it
    for k in range(len(x) - 1):
        ends = (0.0,) if k == len(x) - 2 else tuple(float(a) for a in grid)
        best = {
            a1: min(t + _swing_s(x[k], a0, x[k + 1], a1, v_max, a_max, j_max) for a0, t in best.items())
            for a1 in ends
        }
    return best[0.0]


def through_waypoints_s(path: ArrayLike, limits: JointLimits, scale: float = 1.0) -> float:
    """The least duration of a motion at ``limits`` (× ``scale``) from rest at the first waypoint of
    ``path`` (N × dof, rad) to rest at its last, through the others in order (module docstring)."""
    p = joint_path(path, limits.dof, "path")
    jerk = limits.max_jerk
    slowest = 0.0
    for j in range(limits.dof):
        turns = turning_points(p[:, j])
        v, a = float(limits.max_velocity[j] * scale), float(limits.max_acceleration[j] * scale)
        jm = float(jerk[j] * scale) if jerk is not None else None
        slowest = max(slowest, through_turns_s(turns, v, a, jm))
    return slowest


def stop_to_stop_s(
    path: ArrayLike,
    rests: Sequence[bool],
    limits: JointLimits,
    scale: float = 1.0,
    floors: Mapping[int, float] | None = None,
) -> float:
    """The least duration of a motion through ``path`` that rests at the waypoints ``rests`` flags (and
    at both ends) and flows through the others: the sum of :func:`through_waypoints_s` over its runs.
    ``floors``: what a move from rest to rest ending at a waypoint needs at least whatever the joints may
    do (a guarded touch-down's pace), by that waypoint's index; it counts where it is more."""
    p = joint_path(path, limits.dof, "path")
    if len(rests) != p.shape[0]:
        raise InvalidInputError(f"{len(rests)} rest flags for {p.shape[0]} waypoints")
    stops = sorted({0, p.shape[0] - 1, *(i for i, r in enumerate(rests) if r)})
    floor = floors or {}
    return sum(
        max(through_waypoints_s(p[a : b + 1], limits, scale), floor.get(b, 0.0) if b == a + 1 else 0.0)
        for a, b in pairwise(stops)
    )
