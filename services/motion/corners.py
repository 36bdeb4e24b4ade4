"""Rounded corners for blended motion (pure): where a blended run passes a waypoint, the joined joint
path turns sharply, and a time-optimal timing along it must slow almost to rest there. A corner
rounded within a tolerance keeps the arm moving. The planner decides how far it may round (the tool's
deviation, collisions in both moves' scenes); this module only builds the curve.

The curve is a cubic Bézier from the point ``d`` before the corner to the point ``d`` after it (by
joint-space arc length), tangent to the path at both ends: on two straight lines it is the quadratic
blend with the corner as its control point, the rounding of a UR ``movel`` blend radius or of Pilz's
blend, here in joint space where the path is timed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.kinematics.trajectory import Array

MIN_CORNER_RAD = 0.01  # a rounding shorter than this gains nothing (and crowds the spline)


@dataclass(frozen=True)
class Corner:
    """A rounded corner: the path's rows ``first``..``last`` (inclusive) give way to ``curve``."""

    first: int
    last: int
    curve: Array


def _at(rows: Array, s: Array, value: float) -> tuple[Array, int]:
    """The point at arc length ``value`` and the index of the segment it lies on."""
    k = int(np.clip(np.searchsorted(s, value, side="right") - 1, 0, len(rows) - 2))
    seg = s[k + 1] - s[k]
    a = 0.0 if seg <= 0 else (value - s[k]) / seg
    return rows[k] + a * (rows[k + 1] - rows[k]), k


def _direction(rows: Array, k: int) -> Array:
    v = rows[k + 1] - rows[k]
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


def round_corner(rows: Array, s: Array, corner: int, d: float, step_rad: float) -> Corner | None:
    """The corner at row ``corner`` rounded from arc length ``d`` before it to ``d`` after it (None
    when ``d`` is too short to matter). ``step_rad``: the largest joint-space step between the
    curve's samples. The rows replaced are those strictly between the curve's two ends."""
    if d < MIN_CORNER_RAD or not 0 < corner < len(rows) - 1:
        return None
    a, ka = _at(rows, s, s[corner] - d)
    b, kb = _at(rows, s, s[corner] + d)
    c1 = a + (2.0 / 3.0) * d * _direction(rows, ka)
    c2 = b - (2.0 / 3.0) * d * _direction(rows, kb)
    n = max(4, math.ceil(2.0 * d / step_rad))
    u = np.linspace(0.0, 1.0, n + 1)[:, None]
    curve = (1 - u) ** 3 * a + 3 * (1 - u) ** 2 * u * c1 + 3 * (1 - u) * u**2 * c2 + u**3 * b
    # the rows replaced: after segment ka's start up to segment kb's start (kept rows that sit on the
    # curve's ends would make a near-zero step, which a spline through the points turns into a kink)
    first = ka + 1 if np.linalg.norm(rows[ka] - a) > 0.25 * step_rad or ka == 0 else ka
    last = kb if np.linalg.norm(rows[kb + 1] - b) > 0.25 * step_rad or kb + 1 == len(rows) - 1 else kb + 1
    return Corner(first, last, curve)


def max_rounding(s: Array, corners: list[int], j: int, share: float = 0.45) -> float:
    """The largest ``d`` corner ``j`` of ``corners`` may take: ``share`` of each path piece beside it,
    so neighbouring rounded corners never overlap (the path's two ends are fixed)."""
    marks = [0, *corners, len(s) - 1]
    c = marks[j + 1]
    return share * min(s[c] - s[marks[j]], s[marks[j + 2]] - s[c])


def with_corners(rows: Array, rounded: list[Corner]) -> Array:
    """The path with its corners replaced by their curves (``rounded`` in path order, not overlapping)."""
    out, kept = [], 0
    for c in rounded:
        out.append(rows[kept : c.first])
        out.append(c.curve)
        kept = c.last + 1
    out.append(rows[kept:])
    path = np.vstack(out)
    keep = np.concatenate([[True], np.max(np.abs(np.diff(path, axis=0)), axis=1) > 1e-9])
    return path[keep]
