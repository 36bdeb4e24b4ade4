"""The set-off cut into pieces so that its tail can still be replaced once the grasp plan is in.

The arm sets off toward the object before its grasp is planned, so the set-off ends at rest above the
object. Once the plan is in, the rest of the set-off and the grasp line can flow on as one motion from
where the arm will be (no stop above the object: 0.2-0.3 s of a pick). What the driver has queued
cannot be taken back (a look-ahead of 0.3 s at 1×), so the set-off goes out in pieces, each its own
call that flows on into the next: the tail still unsent when the way on is planned is replaced by it.
Pure: no I/O."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from services.kinematics.trajectory import JointTrajectory

# no cut before this much of the set-off: the grasp plan is not in sooner than 0.2 s at 1×, and by then
# the driver holds 0.3 s of targets ahead (fewer calls: each costs the busy machine a little)
FIRST_CUT_S = 0.42
PIECE_PERIODS = 2  # then a cut every this many streaming periods (0.06 s at 30 ms) ...
# ... but none this close to the end: the arm brakes hard there, little is left to gain and a way on
# from it may not be timeable
LAST_CUT_BEFORE_END_S = 0.09

# a controller clock this much faster than the host's (a twin at --speed 2 or more) has the whole set-off
# queued before any plan comes in (the plan's wall time is that many times longer on its clock, and so is
# the driver's look-ahead): the set-off then goes whole, as the pieces would only cost calls, and whether
# a way on landed would hang on the host's load
FLOWS_ON_BELOW_RATE = 1.5


@dataclass(frozen=True)
class Cut:
    """Where a piece ends: the arm's joints and joint velocity there."""

    index: int  # the piece that ends here
    q: np.ndarray
    qd: np.ndarray


def pieces(traj: JointTrajectory, period_s: float) -> list[JointTrajectory]:
    """``traj`` (at rest at both ends) cut on multiples of the streaming period (no streamed step is
    shortened): up to ``FIRST_CUT_S``, then every ``PIECE_PERIODS`` periods, the last piece at least
    ``LAST_CUT_BEFORE_END_S`` long. Every piece but the last ends in motion; one piece when there is no
    room for a cut."""
    cuts: list[float] = []
    t = np.ceil(FIRST_CUT_S / period_s - 1e-9) * period_s
    while t <= traj.duration - LAST_CUT_BEFORE_END_S + 1e-9:
        cuts.append(float(t))
        t += PIECE_PERIODS * period_s
    bounds = [0.0, *cuts, traj.duration]
    return [traj.window(a, b) for a, b in itertools.pairwise(bounds)]


def cut_after(parts: list[JointTrajectory], index: int) -> Cut | None:
    """The end of piece ``index`` as a place to flow on from (None: the last piece ends at rest)."""
    if not 0 <= index < len(parts) - 1:
        return None
    end = parts[index]
    return Cut(index, end.positions[-1].copy(), end.velocities[-1].copy())
