"""The axis of a rod the gripper holds upright, from the depth points around where it should hang (pure).

A rod grasped off its centre turns in the jaws while it is stood up (its weight twists it about the
jaws' closing axis; seen 1-6° in the twin, the more the farther off centre), so the tool's axis is not
the rod's. Before the touch-down the task asks where the rod really points. The depth points within a
radius of the line the rod should lie on, within its length but for the band the fingers cover and for
its end faces, are the rod's side as the camera sees it. A cylinder of the rod's radius is fitted to
them as the lying-rod detector fits one (:mod:`services.vision.rod`): the residual is the measured depth
less the depth where the pixel's ray meets the cylinder, the direction the sensor's noise acts in,
under a robust loss; a line through the points themselves would follow the noise and the holes of
the black metal (0.5-3° off in the twin; the cylinder fit, a few tenths).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from services.common.errors import InvalidInputError, ObjectNotDetectedError
from services.common.frames import finite_vector, tilt_from_vertical_deg
from services.common.sensors import CameraIntrinsics
from services.vision.geometry import CylinderAxis, project, ray_cylinder_hits, transform_points
from services.vision.lsq import robust_least_squares

Array = NDArray[np.float64]

MIN_POINTS = 40  # fewer: no line worth trusting
MIN_SPAN_M = 0.03  # the points must cover this much of the rod's length, or the direction is loose
END_MARGIN_M = 0.004  # beyond the radius, off each end of the points: the end faces and their edge
LOSS_SCALE_M = 0.002  # the soft-L1 loss's scale: about the depth noise at the working distance


@dataclass(frozen=True)
class HeldRodRegion:
    """Where to look (base frame): a cylinder of ``radius_m`` about the line through ``point`` along
    ``direction``, from ``along_min_m`` to ``along_max_m`` along it, less ``skip_min_m..skip_max_m``
    (the fingers)."""

    point: Array
    direction: Array
    radius_m: float
    along_min_m: float
    along_max_m: float
    skip_min_m: float = 0.0
    skip_max_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("point", "direction"):
            finite_vector(getattr(self, name), 3, f"held rod region: {name}")
        if not np.linalg.norm(self.direction) > 1e-9:
            raise InvalidInputError("held rod region: direction must not be zero")
        bounds = (self.radius_m, self.along_min_m, self.along_max_m, self.skip_min_m, self.skip_max_m)
        if not (np.all(np.isfinite(bounds)) and self.radius_m > 0 and self.along_max_m > self.along_min_m):
            raise InvalidInputError(
                f"held rod region: needs a finite radius > 0 and along_max > along_min, got radius "
                f"{self.radius_m}, along {self.along_min_m}..{self.along_max_m}"
            )

    def unit_direction(self) -> Array:
        d = np.asarray(self.direction, dtype=float)
        return d / np.linalg.norm(d)

    def contains(self, points_base: Array) -> NDArray[np.bool_]:
        """Which of the points (N×3, base frame) lie inside."""
        d = self.unit_direction()
        rel = np.asarray(points_base, dtype=float).reshape(-1, 3) - np.asarray(self.point, dtype=float)
        s = rel @ d
        radial = np.linalg.norm(rel - np.outer(s, d), axis=1)
        inside = (radial < self.radius_m) & (s >= self.along_min_m) & (s <= self.along_max_m)
        return inside & ~((s > self.skip_min_m) & (s < self.skip_max_m))


def region_mask(region: HeldRodRegion, T_base_camera: Array, intr: CameraIntrinsics) -> NDArray[np.bool_]:
    """The pixels (H×W) the region can show in: the box around its axis' two ends in the image, padded
    by its radius there (all of them when an end lies behind the camera). Back-projecting only these
    spares the rest of a 640×480 frame (70-100 ms of a 0.2 s measure in the twin)."""
    mask = np.zeros((intr.height, intr.width), dtype=bool)
    d = region.unit_direction()
    ends = np.asarray(region.point, dtype=float) + np.outer([region.along_min_m, region.along_max_m], d)
    T = np.asarray(T_base_camera, dtype=float)
    ends_c = (ends - T[:3, 3]) @ T[:3, :3]  # into the camera frame
    if np.any(ends_c[:, 2] <= 0.01):
        mask[:] = True
        return mask
    uv = project(ends_c, intr)
    pad = max(intr.fx, intr.fy) * region.radius_m / float(ends_c[:, 2].min()) + 4.0
    u0, v0 = np.floor(uv.min(axis=0) - pad).astype(int)
    u1, v1 = np.ceil(uv.max(axis=0) + pad).astype(int)
    mask[max(v0, 0) : max(v1, 0), max(u0, 0) : max(u1, 0)] = True
    return mask


@dataclass(frozen=True)
class HeldRodAxis:
    direction: Array  # unit, base frame, the way of the region's direction
    point: Array  # on the axis, base frame
    n_points: int
    span_m: float  # how much of the rod's length the points cover
    rms_m: float  # of the depth residuals

    def tilt_deg(self) -> float:
        """Angle between the rod and the vertical."""
        return tilt_from_vertical_deg(self.direction)


def _side_points(points_camera: Array, T_base_camera: Array, region: HeldRodRegion, r: float) -> Array:
    """The camera-frame points of the rod's side: inside ``region``, off its end faces."""
    pc = np.asarray(points_camera, dtype=float).reshape(-1, 3)
    pb = transform_points(T_base_camera, pc)
    inside = region.contains(pb)
    if inside.sum() < MIN_POINTS:
        raise ObjectNotDetectedError(
            f"held rod: {int(inside.sum())} depth points where it should hang (at least {MIN_POINTS} needed)"
        )
    s = pb[inside] @ region.unit_direction()
    side = (s > s.min() + r + END_MARGIN_M) & (s < s.max() - r - END_MARGIN_M)
    if side.sum() < MIN_POINTS:
        raise ObjectNotDetectedError(
            f"held rod: {int(side.sum())} depth points on its side (at least {MIN_POINTS} needed)"
        )
    return pc[inside][side]


def _initial_axis(pc: Array, toward: Array, r: float) -> CylinderAxis:
    """The points' principal line, moved one radius away from the camera (the side seen is in front of
    the axis)."""
    c = pc.mean(axis=0)
    _, _, vt = np.linalg.svd(pc - c, full_matrices=False)
    u = vt[0] if vt[0] @ toward >= 0 else -vt[0]
    away = c - (c @ u) * u  # from the camera to the line, across it
    return CylinderAxis(c + r * away / np.linalg.norm(away), u)


def fit_held_rod_axis(
    points_camera: Array, T_base_camera: Array, region: HeldRodRegion, rod_radius_m: float
) -> HeldRodAxis:
    """The axis of the rod in ``region`` from the depth points (N×3, camera frame). ObjectNotDetectedError
    when too few points, or too short a stretch of the rod, are seen there to trust a direction."""
    T = np.asarray(T_base_camera, dtype=float)
    r = float(rod_radius_m)
    pc = _side_points(points_camera, T, region, r)
    init = _initial_axis(pc, T[:3, :3].T @ region.unit_direction(), r)
    u0, a0 = init.direction, init.point
    e1 = np.cross(u0, a0)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u0, e1)
    z = pc[:, 2]
    rays = pc / z[:, None]

    def axis(x: Array) -> CylinderAxis:
        u = u0 + x[2] * e1 + x[3] * e2
        return CylinderAxis(a0 + x[0] * e1 + x[1] * e2, u / np.linalg.norm(u))

    def residuals(x: Array) -> Array:
        s_in, _, miss = ray_cylinder_hits(rays, axis(x), r)
        return z - s_in + miss

    step = np.array([1e-6, 1e-6, 1e-6, 1e-6])
    fit = robust_least_squares(residuals, np.zeros(4), step=step, loss_scale=LOSS_SCALE_M, tol=step)
    found = axis(fit.x)
    direction = T[:3, :3] @ found.direction
    point = transform_points(T, found.point[None])[0]
    s = (pc - found.point) @ found.direction
    span = float(s.max() - s.min())
    if span < MIN_SPAN_M:
        raise ObjectNotDetectedError(
            f"held rod: its side is seen over {span * 1e3:.0f} mm ({MIN_SPAN_M * 1e3:.0f} mm needed)"
        )
    return HeldRodAxis(direction, point, len(pc), span, float(np.sqrt(np.mean(fit.residuals**2))))
