"""Which grasp offsets along a lying rod to try first: those where the open jaws come down clear of every
box vision saw (pure).

The grasp planner is the authority on a grasp (it checks the whole arm along the whole plan); this only
orders its options. A neighbour beside the rod's centre blocks the jaws there for every wrist option
(the planner then refuses the offset after checking all 48, 0.2-0.6 s, and the cycle asks for the next):
an offset whose jaw footprint already overlaps a seen box goes after those that do not.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from services.task.ports import SeenBox


def jaw_footprint(
    center_xy: np.ndarray, axis_xy: np.ndarray, offset_m: float, along_m: float, across_m: float
) -> np.ndarray:
    """The corners (4×2) of the open jaws' footprint on the table: ``along_m`` along the rod's axis,
    ``across_m`` across it (the opening), centred ``offset_m`` along the axis from the rod's centre."""
    a = np.asarray(axis_xy, dtype=float)[:2]
    a = a / np.linalg.norm(a)
    n = np.array([-a[1], a[0]])
    c = np.asarray(center_xy, dtype=float)[:2] + offset_m * a
    ha, hn = along_m / 2, across_m / 2
    return np.array([c + sa * ha * a + sn * hn * n for sa in (-1, 1) for sn in (-1, 1)])


def overlaps(corners: np.ndarray, box: SeenBox, clearance_m: float) -> bool:
    """Whether the convex polygon ``corners`` comes within ``clearance_m`` of ``box``'s footprint
    (separating axes: the box's two and the polygon's edge normals)."""
    lo = np.asarray(box.min, dtype=float)[:2] - clearance_m
    hi = np.asarray(box.max, dtype=float)[:2] + clearance_m
    box_corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [lo[0], hi[1]], [hi[0], hi[1]]])
    edges = np.diff(np.vstack([corners[[0, 1, 3, 2]], corners[:1]]), axis=0)
    axes = [np.array([1.0, 0.0]), np.array([0.0, 1.0])] + [np.array([-e[1], e[0]]) for e in edges[:2]]
    for ax in axes:
        p, q = corners @ ax, box_corners @ ax
        if p.max() < q.min() or q.max() < p.min():
            return False
    return True


def order_offsets(
    offsets: Sequence[float],
    center_xy: np.ndarray,
    axis_xy: np.ndarray,
    boxes: Sequence[SeenBox],
    along_m: float,
    across_m: float,
    clearance_m: float,
) -> tuple[float, ...]:
    """``offsets`` with those whose jaw footprint is clear of every box first, each group in its given
    order (the configured preference: the centre, then nearer offsets before farther ones)."""
    clear: list[float] = []
    blocked: list[float] = []
    for o in offsets:
        corners = jaw_footprint(center_xy, axis_xy, o, along_m, across_m)
        (blocked if any(overlaps(corners, b, clearance_m) for b in boxes) else clear).append(o)
    return (*clear, *blocked)
