"""Frames, rotations and units (SI inside; mm/deg only at the Dobot wire and in displays).

``T_a_b`` maps points in frame b to frame a. Dobot poses are (x, y, z) in mm and
(rx, ry, rz) in degrees with R = Rz(rz)·Ry(ry)·Rx(rx) (fixed X, then Y, then Z).
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError

Array = NDArray[np.float64]

MM_PER_M = 1000.0


def deg2rad(v: ArrayLike) -> Array:
    return np.deg2rad(np.asarray(v, dtype=float))


def rad2deg(v: ArrayLike) -> Array:
    return np.rad2deg(np.asarray(v, dtype=float))


def finite_vector(v: ArrayLike, n: int | None, name: str) -> Array:
    """Validate a finite float vector of length n; InvalidInputError names what is wrong."""
    try:
        arr = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be numeric, got {v!r}") from exc
    if n is not None and arr.shape[0] != n:
        raise InvalidInputError(f"{name} must have {n} values, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{name} contains NaN or infinite values: {arr.tolist()}")
    return arr


def rotation_angle_rad(R_a: ArrayLike, R_b: ArrayLike) -> float:
    """The angle of the rotation that turns ``R_a`` into ``R_b`` (3×3 rotation matrices), 0..π."""
    R_rel = np.asarray(R_a, dtype=float).T @ np.asarray(R_b, dtype=float)
    return float(np.arccos(np.clip((np.trace(R_rel) - 1.0) / 2.0, -1.0, 1.0)))


def tilt_from_vertical_deg(axis: ArrayLike) -> float:
    """Angle between ``axis`` (either way along it) and the vertical, 0..90°."""
    a = np.asarray(axis, dtype=float).reshape(3)
    return float(np.degrees(np.arccos(np.clip(abs(a[2]) / np.linalg.norm(a), 0.0, 1.0))))


def check_transform(T: ArrayLike, name: str = "transform") -> Array:
    """Validate a 4x4 rigid transform (rotation orthonormal, det +1, last row 0 0 0 1)."""
    M = np.asarray(T, dtype=float)
    if M.shape != (4, 4):
        raise InvalidInputError(f"{name} must be 4x4, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise InvalidInputError(f"{name} contains NaN or infinite values")
    R = M[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or not np.isclose(np.linalg.det(R), 1.0, atol=1e-6):
        raise InvalidInputError(f"{name} rotation is not orthonormal with det +1")
    if not np.allclose(M[3], [0, 0, 0, 1]):
        raise InvalidInputError(f"{name} last row must be [0, 0, 0, 1], got {M[3].tolist()}")
    return M


def make_transform(R: ArrayLike, p: ArrayLike) -> Array:
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=float)
    T[:3, 3] = np.asarray(p, dtype=float)
    return T


def tool_rotation(approach: ArrayLike, closing: ArrayLike) -> Array:
    """Rotation base←tool with tool z = approach and tool y = closing (made orthogonal to it): the tool
    frame of every gripper here (z out of the flange, y the jaws' closing direction, x = y × z)."""
    z = np.asarray(approach, dtype=float)
    z = z / np.linalg.norm(z)
    y = np.asarray(closing, dtype=float)
    y = y - (y @ z) * z
    ny = np.linalg.norm(y)
    if ny < 1e-9:
        raise InvalidInputError("the closing direction must not be parallel to the approach")
    y = y / ny
    return np.column_stack([np.cross(y, z), y, z])


def invert_transform(T: Array) -> Array:
    R, p = T[:3, :3], T[:3, 3]
    return make_transform(R.T, -R.T @ p)


def rpy_deg_to_matrix(rpy_deg: ArrayLike) -> Array:
    """Dobot/URDF rpy (fixed X, Y, Z) in degrees → 3x3 rotation."""
    return Rotation.from_euler("xyz", np.asarray(rpy_deg, dtype=float), degrees=True).as_matrix()


def matrix_to_rpy_deg(R: ArrayLike) -> Array:
    # At ry = ±90° rx and rz are not unique; scipy picks rz = 0 and warns. Any valid pair is fine here.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(np.asarray(R, dtype=float)).as_euler("xyz", degrees=True)


def dobot_pose_to_transform(pose_mm_deg: ArrayLike) -> Array:
    """(x, y, z mm, rx, ry, rz deg) → 4x4 in metres."""
    p = finite_vector(pose_mm_deg, 6, "pose")
    return make_transform(rpy_deg_to_matrix(p[3:]), p[:3] / MM_PER_M)


def transform_to_dobot_pose(T: ArrayLike) -> Array:
    M = np.asarray(T, dtype=float)
    return np.concatenate([M[:3, 3] * MM_PER_M, matrix_to_rpy_deg(M[:3, :3])])


def quat_xyzw_to_matrix(q: ArrayLike) -> Array:
    qa = finite_vector(q, 4, "quaternion")
    n = np.linalg.norm(qa)
    if n < 1e-9:
        raise InvalidInputError("quaternion has zero norm")
    return Rotation.from_quat(qa / n).as_matrix()


def matrix_to_quat_xyzw(R: ArrayLike) -> Array:
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()


def wrap_to_pi(a: ArrayLike) -> Array:
    return (np.asarray(a, dtype=float) + np.pi) % (2 * np.pi) - np.pi
