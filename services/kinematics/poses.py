"""Pose validation and display helpers shared by the motion modules (no heavy imports)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from services.common.errors import InvalidInputError
from services.common.frames import check_transform, transform_to_dobot_pose
from services.kinematics.trajectory import Array

_EYE3 = np.eye(3)


def check_pose(T: ArrayLike, name: str = "target pose") -> Array:
    """A finite rigid 4x4 transform, or InvalidInputError naming what is wrong."""
    try:
        M = np.asarray(T, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be a numeric 4x4 transform, got {T!r}") from exc
    # fast acceptance (IK sits in hot loops); anything doubtful goes to the full check for its message
    if M.shape == (4, 4) and np.isfinite(M).all():
        R = M[:3, :3]
        ortho = float(np.abs(R @ R.T - _EYE3).max())
        det = (
            R[0, 0] * (R[1, 1] * R[2, 2] - R[1, 2] * R[2, 1])
            - R[0, 1] * (R[1, 0] * R[2, 2] - R[1, 2] * R[2, 0])
            + R[0, 2] * (R[1, 0] * R[2, 1] - R[1, 1] * R[2, 0])
        )
        if (
            ortho < 1e-6
            and abs(det - 1.0) < 1e-6
            and M[3, 0] == 0
            and M[3, 1] == 0
            and M[3, 2] == 0
            and M[3, 3] == 1
        ):
            return M
    return check_transform(M, name)


def pose_text(T: Array) -> str:
    """A pose for error messages: position in m and Dobot rpy in degrees."""
    p = transform_to_dobot_pose(T)
    return (
        f"position ({p[0] / 1000:.4f}, {p[1] / 1000:.4f}, {p[2] / 1000:.4f}) m, "
        f"rpy ({p[3]:.2f}, {p[4]:.2f}, {p[5]:.2f})°"
    )
