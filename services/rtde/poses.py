"""UR poses ``[x, y, z, rx, ry, rz]`` (metres, rotation vector in radians) ↔ 4x4 transforms."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation


def pose_to_transform(pose: ArrayLike) -> np.ndarray:
    p = np.asarray(pose, dtype=float)
    if p.shape != (6,) or not np.all(np.isfinite(p)):
        raise ValueError(f"a UR pose is 6 finite numbers [x, y, z, rx, ry, rz], got {pose!r}")
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(p[3:]).as_matrix()
    T[:3, 3] = p[:3]
    return T


def transform_to_pose(T: ArrayLike) -> np.ndarray:
    M = np.asarray(T, dtype=float)
    return np.concatenate([M[:3, 3], Rotation.from_matrix(M[:3, :3]).as_rotvec()])
