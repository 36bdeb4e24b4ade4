"""Conversions shared by every service between numpy and the common protobuf messages."""

from __future__ import annotations

import math

import numpy as np
from pickplace.v1 import common_pb2

from services.common.errors import InvalidInputError
from services.common.frames import make_transform, matrix_to_quat_xyzw, quat_xyzw_to_matrix


def pose_to_matrix(pose: common_pb2.Pose, name: str = "pose") -> np.ndarray:
    """pickplace.v1.Pose → 4x4; InvalidInputError for NaN or a zero quaternion."""
    values = [pose.x, pose.y, pose.z, pose.qx, pose.qy, pose.qz, pose.qw]
    if not all(math.isfinite(v) for v in values):
        raise InvalidInputError(f"{name} contains NaN or infinite values: {values}")
    if math.sqrt(sum(v * v for v in values[3:])) < 1e-9:
        raise InvalidInputError(f"{name} has a zero quaternion (qx, qy, qz, qw all 0)")
    return make_transform(quat_xyzw_to_matrix(values[3:]), values[:3])


def matrix_to_pose(T: np.ndarray) -> common_pb2.Pose:
    q = matrix_to_quat_xyzw(T[:3, :3])
    return common_pb2.Pose(
        x=float(T[0, 3]),
        y=float(T[1, 3]),
        z=float(T[2, 3]),
        qx=float(q[0]),
        qy=float(q[1]),
        qz=float(q[2]),
        qw=float(q[3]),
    )
