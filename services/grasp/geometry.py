"""Small geometry shared by the grasp cores: tool frames, the gripper's outline, carried cylinders.

Tool frame (services.common.frames.tool_rotation): z = approach (out of the flange), y = closing
direction of the jaws, x = y × z.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation, Slerp

from services.common.errors import InvalidInputError
from services.common.frames import finite_vector
from services.common.settings import GraspGripperSettings

Array = np.ndarray

UP = np.array([0.0, 0.0, 1.0])


def unit(v: ArrayLike, name: str) -> Array:
    a = finite_vector(v, 3, name)
    n = float(np.linalg.norm(a))
    if n < 1e-9:
        raise InvalidInputError(f"{name} must be a non-zero vector, got {a.tolist()}")
    return a / n


def pose(R: Array, p: ArrayLike) -> Array:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def gripper_outline_tool(g: GraspGripperSettings, opening_m: float) -> Array:
    """Corners (16, 3) of the two finger boxes and the palm box in the tool frame, jaws at ``opening_m``."""
    half_open = opening_m / 2
    tip = g.fingertip_beyond_tcp_m
    top = tip - g.finger_length_m  # palm bottom (negative: toward the flange)
    xs = (-g.pad_length_m / 2, g.pad_length_m / 2)
    ys = (-(half_open + g.finger_thickness_m), half_open + g.finger_thickness_m)
    fingers = np.array([[x, y, z] for x in xs for y in ys for z in (top, tip)])
    px, py = g.palm_half_xy_m
    palm = np.array([[x, y, z] for x in (-px, px) for y in (-py, py) for z in (top - g.palm_height_m, top)])
    return np.vstack([fingers, palm])


def lowest_gripper_z(g: GraspGripperSettings, T_base_tool: Array, opening_m: float) -> Array:
    """Lowest point (base z) of the gripper outline for one pose (4, 4) or a batch (..., 4, 4)."""
    pts = gripper_outline_tool(g, opening_m)
    T = np.asarray(T_base_tool, dtype=float)
    z = np.einsum("...j,kj->...k", T[..., 2, :3], pts) + T[..., 2, 3][..., None]
    return z.min(axis=-1)


def cylinder_lowest_z(center: Array, axis: Array, radius: float, length: float) -> Array:
    """Lowest point (z) of solid cylinders with centres (..., 3) and unit axes (..., 3)."""
    c = np.asarray(center, dtype=float)
    u = np.asarray(axis, dtype=float)
    uz = u[..., 2]
    rim = radius * np.sqrt(np.clip(1.0 - uz * uz, 0.0, 1.0))
    return c[..., 2] - (length / 2) * np.abs(uz) - rim


def rotation_z(angle: float) -> Array:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# trace(R) within this of -1 (a turn within ~1.8° of a half turn): scipy's slerp decides the way round
HALF_TURN_MARGIN = 1e-3


def _rotation_log(R: Array) -> tuple[Array, float]:
    """Unit axis and angle in [0, π) of a rotation matrix (the shortest rotation, as a slerp takes)."""
    angle = math.acos(max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0)))
    if angle < 1e-9:
        return np.array([0.0, 0.0, 1.0]), 0.0
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return w / (2.0 * math.sin(angle)), angle


def _rotations_about(axis: Array, angles: Array) -> Array:
    """Rotation matrices (n, 3, 3) about one unit axis by each angle (Rodrigues)."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3)[None] + s * K[None] + (1.0 - c) * (K @ K)[None]


def pose_paths(T_a: Array, T_b: Array, n: int) -> Array:
    """:func:`pose_path` with ``n`` steps for B pairs of poses at once: (B, 4, 4) × 2 → (B, n + 1, 4, 4)."""
    T_a, T_b = np.asarray(T_a, dtype=float), np.asarray(T_b, dtype=float)
    s = np.linspace(0.0, 1.0, n + 1)
    out = np.repeat(T_a[:, None], n + 1, axis=1)
    out[:, :, :3, 3] = T_a[:, None, :3, 3] + s[None, :, None] * (T_b[:, None, :3, 3] - T_a[:, None, :3, 3])
    R_rel = np.swapaxes(T_a[:, :3, :3], -1, -2) @ T_b[:, :3, :3]
    trace = np.trace(R_rel, axis1=-2, axis2=-1)
    angle = np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))
    w = np.stack(
        [R_rel[:, 2, 1] - R_rel[:, 1, 2], R_rel[:, 0, 2] - R_rel[:, 2, 0], R_rel[:, 1, 0] - R_rel[:, 0, 1]],
        axis=-1,
    )
    turning = angle >= 1e-9
    axis = np.where(turning[:, None], w / np.where(turning, 2.0 * np.sin(angle), 1.0)[:, None], UP)
    K = np.zeros((len(axis), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = axis[:, 2], -axis[:, 1], axis[:, 0]
    phi = s[None, :] * np.where(turning, angle, 0.0)[:, None]  # (B, n + 1)
    sin, cos = np.sin(phi)[..., None, None], np.cos(phi)[..., None, None]
    R = np.eye(3) + sin * K[:, None] + (1.0 - cos) * (K @ K)[:, None]
    out[:, :, :3, :3] = T_a[:, None, :3, :3] @ R
    out[:, -1, :3, :3] = T_b[:, :3, :3]
    for b in np.nonzero(trace <= -1.0 + HALF_TURN_MARGIN)[0]:  # the way round is scipy's choice there
        out[b] = pose_path(T_a[b], T_b[b], 1.0, n)
    return out


def pose_path(T_a: Array, T_b: Array, step_m: float, n: int | None = None) -> Array:
    """Tool poses (n + 1, 4, 4) on the straight line a → b (position lerp, orientation slerp), both ends
    included; ``n`` steps, or as keep each step ≤ ``step_m``."""
    d = float(np.linalg.norm(T_b[:3, 3] - T_a[:3, 3]))
    n = n or max(1, math.ceil(d / step_m))
    s = np.linspace(0.0, 1.0, n + 1)
    out = np.repeat(T_a[None], n + 1, axis=0)
    out[:, :3, 3] = T_a[:3, 3] + s[:, None] * (T_b[:3, 3] - T_a[:3, 3])
    R_rel = T_a[:3, :3].T @ T_b[:3, :3]
    if float(np.trace(R_rel)) > -1.0 + HALF_TURN_MARGIN:
        # slerp in closed form (scipy's Slerp costs ~0.4 ms a call, and a rod plan makes hundreds)
        axis, angle = _rotation_log(R_rel)
        out[:, :3, :3] = T_a[:3, :3][None] @ _rotations_about(axis, s * angle)
        out[-1, :3, :3] = T_b[:3, :3]
    else:  # about a half turn the way round is ambiguous: scipy's choice, as everywhere else
        rots = Rotation.from_matrix(np.stack([T_a[:3, :3], T_b[:3, :3]]))
        out[:, :3, :3] = Slerp([0.0, 1.0], rots)(s).as_matrix()
    return out
