"""Depth back-projection and the table plane (pure numpy, vectorised).

Pixel (u, v) integer coordinates are pixel centres (the OpenCV convention); a
depth z at (u, v) is the point ((u - cx) z / fx, (v - cy) z / fy, z) in the
camera frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from services.common.errors import InvalidInputError, VisionError
from services.common.sensors import CameraIntrinsics

Array = np.ndarray

REFERENCE_WIDTH_PX = 640  # pixel counts and strides in the settings are for a 640-px-wide image


def resolution_scale(intr: CameraIntrinsics) -> float:
    """Image width relative to 640 px: strides scale by it, pixel counts by its square."""
    return intr.width / REFERENCE_WIDTH_PX


def scaled_stride(stride: int, intr: CameraIntrinsics) -> int:
    return max(1, round(stride * resolution_scale(intr)))


@lru_cache(maxsize=8)
def _ray_grid(width: int, height: int, fx: float, fy: float, cx: float, cy: float) -> tuple[Array, Array]:
    xs = (np.arange(width, dtype=np.float32) - np.float32(cx)) / np.float32(fx)
    ys = (np.arange(height, dtype=np.float32) - np.float32(cy)) / np.float32(fy)
    xs.setflags(write=False)
    ys.setflags(write=False)
    return xs, ys


def ray_factors(intr: CameraIntrinsics) -> tuple[Array, Array]:
    """Per-column x/z and per-row y/z of the pixel-centre rays (cached per intrinsics)."""
    return _ray_grid(intr.width, intr.height, float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy))


def pixel_rays(intr: CameraIntrinsics, rows: Array, cols: Array) -> Array:
    """(N, 3) rays with z = 1 through the given pixel centres."""
    xs, ys = ray_factors(intr)
    out = np.empty((len(rows), 3))
    out[:, 0] = xs[cols]
    out[:, 1] = ys[rows]
    out[:, 2] = 1.0
    return out


def backproject(
    depth_m: Array,
    intr: CameraIntrinsics,
    stride: int = 1,
    mask: Array | None = None,
    z_min: float = 0.0,
    z_max: float = np.inf,
) -> tuple[Array, Array, Array]:
    """Valid depth pixels (optionally masked, strided) → (points (N,3) camera frame, rows, cols)."""
    d = depth_m[::stride, ::stride]
    valid = (d > z_min) & (d < z_max) & np.isfinite(d)
    if mask is not None:
        valid &= mask[::stride, ::stride]
    r, c = np.nonzero(valid)
    z = d[r, c].astype(np.float64)
    rows, cols = r * stride, c * stride
    xs, ys = ray_factors(intr)
    pts = np.empty((len(z), 3))
    pts[:, 0] = xs[cols] * z
    pts[:, 1] = ys[rows] * z
    pts[:, 2] = z
    return pts, rows, cols


def project(points: Array, intr: CameraIntrinsics) -> Array:
    """Camera-frame points → (N, 2) pixel coordinates (u, v)."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    return np.column_stack([intr.fx * p[:, 0] / p[:, 2] + intr.cx, intr.fy * p[:, 1] / p[:, 2] + intr.cy])


def transform_points(T: Array, points: Array) -> Array:
    p = np.asarray(points, dtype=float)
    return p @ T[:3, :3].T + T[:3, 3]


@dataclass(frozen=True)
class Plane:
    """n·p + d = 0 with unit n pointing toward the camera (the camera origin has n·0 + d = d > 0)."""

    normal: Array
    d: float
    inlier_fraction: float = 1.0
    rms_m: float = 0.0

    def signed_distance(self, points: Array) -> Array:
        """Height above the plane (positive on the camera's side)."""
        return np.asarray(points) @ self.normal + self.d

    def project(self, points: Array) -> Array:
        p = np.asarray(points, dtype=float)
        return p - np.outer(self.signed_distance(p), self.normal)

    def intersect_rays(self, rays: Array, offset_m: float = 0.0) -> Array:
        """Points where rays from the camera origin meet the plane raised by ``offset_m`` (NaN if parallel/behind)."""
        denom = rays @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offset_m - self.d) / denom
        t = np.where((np.abs(denom) > 1e-9) & (t > 0), t, np.nan)
        return rays * t[:, None]


def _plane_from_points(p0: Array, p1: Array, p2: Array) -> tuple[Array, Array]:
    n = np.cross(p1 - p0, p2 - p0)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.divide(n, norm, out=np.zeros_like(n), where=norm > 1e-12)
    d = -np.sum(n * p0, axis=-1)
    return n, d


def _lsq_plane(points: Array) -> tuple[Array, float]:
    """Total-least-squares plane: normal = eigenvector of the scatter matrix with the least variance."""
    c = points.mean(axis=0)
    q = points - c
    _, evecs = np.linalg.eigh(q.T @ q)
    n = evecs[:, 0]
    return n, float(-n @ c)


def fit_plane_ransac(
    points: Array,
    threshold_m: float,
    iterations: int = 128,
    rng: np.random.Generator | None = None,
    max_points: int = 3000,
    min_inlier_fraction: float = 0.2,
) -> Plane:
    """The dominant plane of a cloud: vectorised RANSAC on a subsample, then least squares on inliers.

    All hypotheses are scored at once (iterations × points distance matrix). The result is oriented
    toward the camera (d > 0). Raises VisionError when no plane holds ``min_inlier_fraction``.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InvalidInputError(f"plane fit needs an (N, 3) cloud, got shape {pts.shape}")
    if len(pts) < 3:
        raise VisionError(f"plane fit needs at least 3 points with depth, got {len(pts)}")
    rng = rng or np.random.default_rng(0)
    sub = pts if len(pts) <= max_points else pts[rng.integers(0, len(pts), max_points)]
    idx = rng.integers(0, len(sub), size=(iterations, 3))
    n, d = _plane_from_points(sub[idx[:, 0]], sub[idx[:, 1]], sub[idx[:, 2]])
    dist = sub @ n.T
    dist += d  # (N_sub, iterations) signed distances
    counts = np.count_nonzero(np.abs(dist) < threshold_m, axis=0)
    counts[np.linalg.norm(n, axis=1) < 0.5] = 0
    best = int(np.argmax(counts))
    if counts[best] < min_inlier_fraction * len(sub):
        raise VisionError(
            f"no table plane: best plane holds {counts[best]}/{len(sub)} points "
            f"(< {min_inlier_fraction:.0%} within {threshold_m} m)"
        )
    normal, offset = n[best], float(d[best])
    # Refine twice by least squares on the inliers (removes the 3-point hypothesis noise); an even
    # subsample of a large cloud gives the same plane to well under a millimetre.
    fit_pts = pts if len(pts) <= 4 * max_points else pts[:: len(pts) // (4 * max_points) + 1]
    for _ in range(2):
        inl = np.abs(fit_pts @ normal + offset) < threshold_m
        normal, offset = _lsq_plane(fit_pts[inl])
    if offset < 0:
        normal, offset = -normal, -offset
    res = pts @ normal + offset
    inl = np.abs(res) < threshold_m
    return Plane(
        normal=normal,
        d=offset,
        inlier_fraction=float(inl.mean()),
        rms_m=float(np.sqrt(np.mean(res[inl] ** 2))),
    )


@dataclass(frozen=True)
class CylinderAxis:
    """A cylinder's axis: a point on it and its direction."""

    point: Array  # a point on the axis
    direction: Array  # unit


def ray_cylinder_hits(rays: Array, axis: CylinderAxis, r: float) -> tuple[Array, Array, Array]:
    """Ray parameters (= depth for z = 1 rays) where rays enter/leave the infinite cylinder.

    Returns (s_in, s_out, miss): ``miss`` > 0 for rays that pass the cylinder (then s_in = s_out =
    the closest approach) and grows with the distance by which they miss.
    """
    u, a0 = axis.direction, axis.point
    du = rays @ u
    w = rays - np.outer(du, u)
    q = -(a0 - (a0 @ u) * u)
    A = np.maximum(np.einsum("ij,ij->i", w, w), 1e-12)
    B = 2.0 * (w @ q)
    C = q @ q - r * r
    disc = B * B - 4 * A * C
    sq = np.sqrt(np.abs(disc)) / (2 * A)
    mid = -B / (2 * A)
    hit = disc >= 0
    s_in = np.where(hit, mid - sq, mid)
    s_out = np.where(hit, mid + sq, mid)
    return s_in, s_out, np.where(hit, 0.0, sq)
