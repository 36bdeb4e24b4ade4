"""Resuming a ServoJ stream after the controller ran dry (pure).

A ServoJ target reaches its position in its ``t``; a controller that runs out of targets holds the last
one, at rest. The stream's next planned target would then be a step in speed from rest (the
trajectory's full speed in one period: far above the acceleration limits). So a stream that has run
dry is never simply continued: the rest of it is re-timed from rest along the same path — the planned
targets followed at a rate that rises smoothly from 0 to the plan's own (a smoothstep in time), so the
arm accelerates within its limits and, once the ramp is over, follows the plan's targets exactly.

The ramp is lengthened until every streamed target passes the same speed, acceleration, joint and
workspace checks as any other (:class:`services.robot.safety.SafetyLimits`); if none does within
``MAX_RAMP_S``, nothing is sent and the stream fails.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.errors import LimitViolationError
from services.robot.safety import SafetyLimits

MAX_RAMP_S = 4.0  # the longest ramp tried: beyond it the rest of the stream is refused


@dataclass(frozen=True)
class Resumed:
    targets: np.ndarray  # (n, dof): the ServoJ targets from rest to the stream's last target
    ramp_s: float  # how long the rate takes to reach the plan's
    reaches_plan: bool  # the ramp ends before the stream does: its last targets are the plan's own


def check_from_rest(
    targets: np.ndarray, rest: np.ndarray, period_s: float, limits: SafetyLimits, what: str
) -> None:
    """ServoJ ``targets`` streamed from an arm at rest at ``rest``: speeds, accelerations, joint and
    workspace limits, as every stream is checked. LimitViolationError names the first breach."""
    limits.check_velocities(targets, period_s, q_start=rest)
    limits.check_accelerations(targets, period_s, np.vstack([rest, rest]))
    limits.check_all(targets, what)


def warp(steps: int, half: int, end: float) -> np.ndarray:
    """Plan positions (in targets after the rest point) of the re-timed targets: the plan's rate rises
    from 0 to 1 over ``2 * half`` periods (smoothstep: no step in acceleration either), after which the
    targets fall on the plan's own; the last one is ``end`` exactly."""
    j = np.arange(1, steps + 1, dtype=float)
    x = j / (2 * half)
    u = np.where(x < 1.0, 2 * half * (x**3 - x**4 / 2.0), j - half)
    return np.minimum(u, end)


def smoothstep5(x: np.ndarray) -> np.ndarray:
    """The quintic smoothstep on [0, 1]: 0 to 1 with zero speed and acceleration at both ends."""
    return x**3 * (10.0 - 15.0 * x + 6.0 * x**2)


def _sample(points: np.ndarray, u: np.ndarray) -> np.ndarray:
    i = np.minimum(np.floor(u).astype(int), len(points) - 2)
    f = (u - i)[:, None]
    return points[i] * (1.0 - f) + points[i + 1] * f


def retime_from_rest(
    q_rest: np.ndarray, remaining: np.ndarray, period_s: float, limits: SafetyLimits
) -> Resumed:
    """The rest of a stream (``remaining``: its unsent targets, one period apart, continuing from
    ``q_rest``) re-timed to start from rest at ``q_rest``. LimitViolationError when no ramp up to
    ``MAX_RAMP_S`` keeps it within the limits."""
    rest = np.asarray(q_rest, dtype=float)
    points = np.vstack([rest[None], np.asarray(remaining, dtype=float).reshape(-1, rest.size)])
    end = float(len(points) - 1)
    last: LimitViolationError | None = None
    half = 2
    while 2 * half * period_s <= MAX_RAMP_S:
        # steps until the warp reaches the end: within the ramp it covers half its length
        steps = int(np.ceil(end + half)) if end >= half else 2 * half
        u = warp(steps, half, end)
        u = u[: int(np.searchsorted(u, end)) + 1]  # up to (and with) the first that reaches the end
        targets = _sample(points, u)
        try:
            check_from_rest(targets, rest, period_s, limits, "re-timed trajectory")
        except LimitViolationError as exc:
            last = exc
            half *= 2
            continue
        return Resumed(targets, 2 * half * period_s, reaches_plan=end >= half + 1)
    to_rest = _to_rest(points, end, rest, period_s, limits)
    if to_rest is not None:
        return to_rest
    raise LimitViolationError(
        f"the rest of the stream cannot be resumed from rest within {MAX_RAMP_S:.1f} s of ramp: {last}"
    )


def _to_rest(
    points: np.ndarray, end: float, rest: np.ndarray, period_s: float, limits: SafetyLimits
) -> Resumed | None:
    """The rest of the stream from rest to rest at its last target along the same path (a quintic
    smoothstep in time: no step in speed or acceleration at either end), the shortest that passes every
    check; None if none within ``MAX_RAMP_S``. The last resort for a short stream that ends in motion
    and runs at its limits: no ramp reaches its rate before its end (the clamp at the end was a step
    from speed to rest), and none short enough to reach it stays within them (seed 1000 of the eval
    under load: the 18 targets of a line out of the release, 753°/s² at the clamp). It ends at rest, so
    what was to continue it is planned again from there."""
    n = max(4, int(np.ceil(end)))
    while n * period_s <= MAX_RAMP_S:
        x = np.arange(1, n + 1, dtype=float) / n
        targets = _sample(points, end * smoothstep5(x))
        try:
            check_from_rest(targets, rest, period_s, limits, "re-timed trajectory")
        except LimitViolationError:
            n = int(np.ceil(n * 1.5))
            continue
        return Resumed(targets, n * period_s, reaches_plan=False)
    return None


EASE_IN_SPANS_S = (0.1, 0.2, 0.4, 0.8, 1.6)  # how long the start offset may take to fade, shortest first


def ease_in_offset(
    q_now: np.ndarray, start: np.ndarray, targets: np.ndarray, period_s: float, limits: SafetyLimits
) -> np.ndarray:
    """The ``targets`` of a plan from rest at ``start``, a hair off ``q_now``, with that offset faded out.

    Each target is moved by the offset (``q_now`` − the plan's start) times a weight that falls from 1 to
    0 along a quintic smoothstep (no step in speed or acceleration), so the stream starts where the arm
    is and ends on the plan's own targets; the shortest fade whose targets pass every check is taken.
    LimitViolationError when none does."""
    targets = np.asarray(targets, dtype=float).reshape(-1, np.asarray(q_now).size)
    rest = np.asarray(q_now, dtype=float)
    offset = rest - np.asarray(start, dtype=float)
    last: LimitViolationError | None = None
    for span in EASE_IN_SPANS_S:
        n = max(1, min(len(targets), round(span / period_s)))
        x = np.minimum(np.arange(1, len(targets) + 1) / n, 1.0)
        weight = 1.0 - smoothstep5(x)
        eased = targets + weight[:, None] * offset[None, :]
        try:
            check_from_rest(eased, rest, period_s, limits, "eased-in trajectory")
        except LimitViolationError as exc:
            last = exc
            continue
        return eased
    raise LimitViolationError(f"the plan's start offset cannot be faded out within the limits: {last}")
