"""Pose validation and display helpers shared by the motion modules (no heavy imports)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from services.common.errors import InvalidInputError
from services.common.frames import check_transform, transform_to_dobot_pose
from services.kinematics.trajectory import Array


def check_pose(T: ArrayLike, name: str = "target pose") -> Array:
    """A finite rigid 4x4 transform, or InvalidInputError naming what is wrong."""
    try:
        M = np.asarray(T, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be a numeric 4x4 transform, got {T!r}") from exc
    # fast acceptance in plain floats (IK sits in hot loops); anything doubtful goes to the full
    # check for its message
    if M.shape == (4, 4):
        (a, b, c, x), (d, e, f, y), (g, h, i, z), last = M.tolist()
        if (
            last == [0.0, 0.0, 0.0, 1.0]
            and math.isfinite(a + b + c + d + e + f + g + h + i + x + y + z)
            and max(
                abs(a * a + b * b + c * c - 1.0),
                abs(d * d + e * e + f * f - 1.0),
                abs(g * g + h * h + i * i - 1.0),
                abs(a * d + b * e + c * f),
                abs(a * g + b * h + c * i),
                abs(d * g + e * h + f * i),
                abs(a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) - 1.0),
            )
            < 1e-6
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
