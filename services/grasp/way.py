"""The way a carried object goes between two places on the table, and what stands under it (pure)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from services.common.frames import wrap_to_pi
from services.kinematics.collision import Box

Array = np.ndarray

# A carry is a joint move: the tool swings about the base between its two ends, its path bowing out or in
# a little from the ring sector between their bearings. A box this close to that sector is under the way.
WAY_MARGIN_M = 0.10
FOOTPRINT_STEP_M = 0.01  # points sampled over a box's footprint for the test


def carry_height(
    minimum_m: float, clearance_m: float, start_xy: Array, end_xy: Array, hang_m: float, boxes: Sequence[Box]
) -> float:
    """The tool tip's height for carrying from above ``start_xy`` to above ``end_xy``: ``minimum_m`` at
    least, and ``clearance_m`` above the top of every box under the way with what hangs ``hang_m`` below
    the tip (a carried cube, a rod standing in the jaws, the fingertips). Under the way: any point of
    the box's footprint within ``WAY_MARGIN_M`` of the ring sector the tool sweeps about the base (the
    bearings between the two ends, the shorter way round; the radii between theirs)."""
    a0, a1 = math.atan2(start_xy[1], start_xy[0]), math.atan2(end_xy[1], end_xy[0])
    sweep = float(wrap_to_pi(a1 - a0))  # the shorter way round
    r0, r1 = float(np.hypot(*start_xy[:2])), float(np.hypot(*end_xy[:2]))
    r_lo, r_hi = min(r0, r1) - WAY_MARGIN_M, max(r0, r1) + WAY_MARGIN_M
    height = float(minimum_m)
    for box in boxes:
        top = box.max[2] + clearance_m + hang_m
        if top <= height:
            continue
        xs, ys = (_samples(box.min[k], box.max[k]) for k in (0, 1))
        px, py = (v.ravel() for v in np.meshgrid(xs, ys))
        r = np.hypot(px, py)
        # the bearing from the start, the way the tool swings; the margin as an angle at each point's radius
        rel = wrap_to_pi(np.arctan2(py, px) - a0)
        along = rel * math.copysign(1.0, sweep) if sweep else np.abs(rel)
        slack = WAY_MARGIN_M / np.maximum(r, WAY_MARGIN_M)
        within = (r >= r_lo) & (r <= r_hi) & (along >= -slack) & (along <= abs(sweep) + slack)
        if bool(np.any(within)):
            height = top
    return height


def _samples(lo: float, hi: float) -> Array:
    """Points from ``lo`` to ``hi``, both ends included, at most ``FOOTPRINT_STEP_M`` apart."""
    return np.linspace(lo, hi, max(2, math.ceil((hi - lo) / FOOTPRINT_STEP_M) + 1))
