"""UR poses ``[x, y, z, rx, ry, rz]`` (metres, rotation vector in radians) ↔ 4x4 transforms.

Closed forms in plain floats (Rodrigues and its inverse): a simulated controller converts two poses
every 2 ms cycle and a link one per package, where scipy's Rotation costs ~0.1 ms a call.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

NEAR_ZERO = 1e-9
LARGE_ANGLE = 2.0  # rad: beyond it the rotation axis comes from the symmetric part of R


def pose_to_transform(pose: ArrayLike) -> np.ndarray:
    p = np.asarray(pose, dtype=float)
    if p.shape != (6,) or not np.all(np.isfinite(p)):
        raise ValueError(f"a UR pose is 6 finite numbers [x, y, z, rx, ry, rz], got {pose!r}")
    x, y, z, rx, ry, rz = p.tolist()
    th = math.sqrt(rx * rx + ry * ry + rz * rz)
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    if th < NEAR_ZERO:
        return T
    kx, ky, kz = rx / th, ry / th, rz / th
    c, s = math.cos(th), math.sin(th)
    v = 1.0 - c
    T[:3, :3] = (
        (c + kx * kx * v, kx * ky * v - kz * s, kx * kz * v + ky * s),
        (ky * kx * v + kz * s, c + ky * ky * v, ky * kz * v - kx * s),
        (kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v),
    )
    return T


def transform_to_pose(T: ArrayLike) -> np.ndarray:
    M = np.asarray(T, dtype=float)
    (r00, r01, r02, x), (r10, r11, r12, y), (r20, r21, r22, z) = M[:3].tolist()
    # the angle from both its cosine (trace) and its sine (skew part): acos alone loses half the
    # digits near 0 and near a half turn
    cos_th = max(-1.0, min(1.0, (r00 + r11 + r22 - 1.0) / 2.0))
    sin_th = 0.5 * math.sqrt((r21 - r12) ** 2 + (r02 - r20) ** 2 + (r10 - r01) ** 2)
    th = math.atan2(sin_th, cos_th)
    if th < NEAR_ZERO:
        return np.array([x, y, z, 0.0, 0.0, 0.0])
    if th < LARGE_ANGLE:
        f = th / (2.0 * sin_th)
        return np.array([x, y, z, f * (r21 - r12), f * (r02 - r20), f * (r10 - r01)])
    # towards a half turn sin(th) vanishes: the axis from the symmetric part, k k^T = (S - cos I) /
    # (1 - cos) with S = (R + R^T) / 2, the column of the largest diagonal entry, its sign from the
    # skew part (which is 2 sin(th) k)
    d = 1.0 - cos_th
    kk = (
        ((r00 - cos_th) / d, (r01 + r10) / (2 * d), (r02 + r20) / (2 * d)),
        ((r01 + r10) / (2 * d), (r11 - cos_th) / d, (r12 + r21) / (2 * d)),
        ((r02 + r20) / (2 * d), (r12 + r21) / (2 * d), (r22 - cos_th) / d),
    )
    i = max(range(3), key=lambda j: kk[j][j])
    col = kk[i]
    n = math.sqrt(col[0] ** 2 + col[1] ** 2 + col[2] ** 2)
    k = [c / n for c in col]
    skew = (r21 - r12, r02 - r20, r10 - r01)
    if k[0] * skew[0] + k[1] * skew[1] + k[2] * skew[2] < 0:
        k = [-c for c in k]
    return np.array([x, y, z, th * k[0], th * k[1], th * k[2]])
