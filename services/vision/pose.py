"""The LLD §3.4.1 PCA pose estimator, with right-handed frames and a validated quaternion.

Differences from the LLD sketch, on purpose: ``eigh`` (the covariance is
symmetric, so eigenvalues are real and sorted), a deterministic sign for every
axis (the first two axes point along +x/+y of the input frame where they can,
the third completes a right-handed frame), and the rotation is checked to be
orthonormal with det +1 before scipy converts it to a quaternion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError, PoseEstimationError
from services.common.frames import check_transform, make_transform

Array = np.ndarray

MIN_POINTS = 10


@dataclass(frozen=True)
class PcaPose:
    position: Array  # centroid (3,)
    rotation: Array  # (3, 3) columns = principal axes, largest variance first, right-handed
    quat_xyzw: Array  # (4,) with w >= 0
    eigenvalues: Array  # (3,) descending variances (m²)

    @property
    def transform(self) -> Array:
        return make_transform(self.rotation, self.position)


def rotation_to_quaternion(R: Array) -> Array:
    """3x3 rotation → unit quaternion (x, y, z, w), w >= 0; InvalidInputError if R is not a rotation."""
    M = np.asarray(R, dtype=float)
    if M.shape != (3, 3):
        raise InvalidInputError(f"rotation must be 3x3, got shape {M.shape}")
    check_transform(make_transform(M, np.zeros(3)), "rotation")
    q = Rotation.from_matrix(M).as_quat()
    return q if q[3] >= 0 else -q


def estimate_pca_pose(points: Array) -> PcaPose:
    """Centroid + principal axes of an (N, 3) cloud as a right-handed pose."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InvalidInputError(f"PCA pose needs an (N, 3) point array, got shape {pts.shape}")
    if len(pts) < MIN_POINTS:
        raise PoseEstimationError(f"PCA pose needs at least {MIN_POINTS} points, got {len(pts)}")
    if not np.all(np.isfinite(pts)):
        raise InvalidInputError("PCA pose input contains NaN or infinite coordinates")
    centroid = pts.mean(axis=0)
    cov = np.cov((pts - centroid).T)
    evals, evecs = np.linalg.eigh(cov)
    order = np.argsort(evals)[::-1]
    evals, axes = evals[order], evecs[:, order]
    if evals[0] <= 1e-18:
        raise PoseEstimationError("PCA pose: all points coincide, no principal axis")
    # Deterministic signs: axis k points along +e_k where it has a component, else along its largest one.
    for k in range(2):
        a = axes[:, k]
        ref = a[k] if abs(a[k]) > 1e-9 else a[np.argmax(np.abs(a))]
        if ref < 0:
            axes[:, k] = -a
    axes[:, 2] = np.cross(axes[:, 0], axes[:, 1])
    quat = rotation_to_quaternion(axes)
    return PcaPose(position=centroid, rotation=axes, quat_xyzw=quat, eigenvalues=np.maximum(evals, 0.0))
