"""Standing a held rod straight before its touch-down (pure): where vision should look for it, the turn that
brings the axis it measured to the vertical, and the rest of the plan turned as much.

A rod grasped off its centre turns in the jaws while it is stood up: its weight twists it about the jaws'
closing axis (in the twin, 1-6° by the time it hangs above the place, the more the farther off centre
it is held; a centred grasp stays within a few tenths). The tool is turned about its own centre, where
the jaws hold the rod, so the rod's foot comes down where it was to; what follows the touch-down (the
release, the way out) is turned with it about the touch-down point.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.modes import MotionKind
from services.task.ports import GraspPlan, HeldRodQuery, SeenRod

SEARCH_MARGIN_M = 0.015  # around the rod's radius: the lean of a few degrees along its length
FINGER_MARGIN_M = 0.008  # beyond the fingers' half width along the rod: their edges in the depth image
TABLE_MARGIN_M = 0.012  # above the table: its surface around the rod's foot is not the rod


def held_rod_query(
    T_base_tool: np.ndarray, rod: SeenRod, grasp_offset_m: float, finger_width_m: float, table_z_m: float
) -> HeldRodQuery:
    """Where the rod held at ``T_base_tool`` (its axis along the tool's x, the jaws at the tool's centre)
    hangs: up to its half length and the grasp offset either way along the tool's x (pointing up), above
    the table, less the band the fingers cover."""
    T = np.asarray(T_base_tool, dtype=float)
    p = T[:3, 3]
    up = T[:3, 0] if T[2, 0] >= 0 else -T[:3, 0]
    reach = rod.length / 2 + abs(grasp_offset_m) + SEARCH_MARGIN_M
    lowest = -reach
    if up[2] > 0.1:  # the table below: not the rod
        lowest = max(lowest, (table_z_m + TABLE_MARGIN_M - p[2]) / up[2])
    band = finger_width_m / 2 + FINGER_MARGIN_M
    return HeldRodQuery(
        point=p.copy(),
        direction=up.copy(),
        search_radius_m=rod.diameter / 2 + SEARCH_MARGIN_M,
        along_min_m=float(lowest),
        along_max_m=float(reach),
        skip_min_m=-band,
        skip_max_m=band,
        rod_diameter_m=rod.diameter,
    )


def straightening(axis: np.ndarray) -> np.ndarray:
    """The least rotation (3×3) that brings ``axis`` (either way along it) to the vertical."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    if a[2] < 0:
        a = -a
    cross = np.cross(a, [0.0, 0.0, 1.0])
    s = float(np.linalg.norm(cross))
    if s < 1e-12:
        return np.eye(3)
    angle = float(np.arctan2(s, a[2]))
    return Rotation.from_rotvec(cross / s * angle).as_matrix()


def turned(T: np.ndarray, R: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """The pose ``T`` turned by ``R`` about the point ``pivot`` (base frame)."""
    out = np.asarray(T, dtype=float).copy()
    out[:3, :3] = R @ out[:3, :3]
    out[:3, 3] = pivot + R @ (out[:3, 3] - pivot)
    return out


def turn_from(plan: GraspPlan, first: int, R: np.ndarray) -> list[int]:
    """Turn the waypoints from ``first`` (the touch-down) on by ``R`` about the touch-down's tool point,
    up to the first joint move (the way home goes where it went); returns the indices turned. Their joint
    positions are planned again from the poses."""
    pivot = np.asarray(plan.waypoints[first].T_base_tool, dtype=float)[:3, 3].copy()
    done = []
    for k in range(first, len(plan.waypoints)):
        w = plan.waypoints[k]
        if w.motion is MotionKind.JOINT:
            break
        plan.waypoints[k] = replace(w, T_base_tool=turned(w.T_base_tool, R, pivot))
        done.append(k)
    return done
