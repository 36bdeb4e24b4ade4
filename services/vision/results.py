"""What the vision cores return: rods, cubes and obstacles in the camera and base frames."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from services.vision.geometry import Plane
from services.vision.pose import rotation_to_quaternion

Array = np.ndarray


def _frame_from_axis(axis: Array, up: Array) -> Array:
    """Right-handed rotation with x along ``axis`` and z as close to ``up`` as x allows."""
    x = axis / np.linalg.norm(axis)
    z = up - (up @ x) * x
    z /= np.linalg.norm(z)
    return np.column_stack([x, np.cross(z, x), z])


class Visibility(Enum):
    """How much of an object the camera sees: a cut or occluded cube is not fitted as a whole one."""

    WHOLE = "whole"
    CUT_BY_EDGE = "cut_by_edge"  # part of it lies outside the image
    OCCLUDED = "occluded"  # something nearer hides part of it


@dataclass(frozen=True)
class RodDetection:
    """A rod lying on the table. ``axis`` is a unit vector (sign canonical: +x in the camera image)."""

    center_cam: Array
    axis_cam: Array
    up_cam: Array  # table normal (toward the camera side)
    length_m: float
    diameter_m: float
    confidence: float
    method: str  # "surface_fit" (depth on the rod) or "silhouette" (colour mask + table plane + radius)
    n_depth_points: int
    n_pixels: int
    endpoints_px: Array  # (2, 2) image positions of the two ends, for overlays
    center_base: Array | None = None
    axis_base: Array | None = None
    up_base: Array | None = None

    @property
    def rotation_cam(self) -> Array:
        """Object frame: x along the axis, z up from the table."""
        return _frame_from_axis(self.axis_cam, self.up_cam)

    @property
    def quat_cam(self) -> Array:
        return rotation_to_quaternion(self.rotation_cam)

    @property
    def rotation_base(self) -> Array | None:
        if self.axis_base is None or self.up_base is None:
            return None
        return _frame_from_axis(self.axis_base, self.up_base)

    @property
    def quat_base(self) -> Array | None:
        R = self.rotation_base
        return None if R is None else rotation_to_quaternion(R)

    def in_base(self, T_base_camera: Array) -> RodDetection:
        R, p = T_base_camera[:3, :3], T_base_camera[:3, 3]
        return replace(
            self, center_base=R @ self.center_cam + p, axis_base=R @ self.axis_cam, up_base=R @ self.up_cam
        )


@dataclass(frozen=True)
class CubeDetection:
    centroid_cam: Array  # cube centre (not the centroid of the visible points)
    color_label: str  # black | red | blue | green | unknown
    n_points: int  # full-resolution pixels of the cluster (estimated from the strided cloud)
    rotation_cam: Array  # x, y along the cube's faces, z up from the table
    fit_rms_m: float
    image_uv: Array  # (2,) pixel of the centre, for overlays
    centroid_base: Array | None = None
    rotation_base: Array | None = None
    mean_rgb: Array | None = None  # mean colour of its pixels (what an "unknown" colour was)
    visibility: Visibility = Visibility.WHOLE
    hidden_fraction: float = 0.0  # share of its camera-facing surface hidden by something nearer

    @property
    def quat_cam(self) -> Array:
        return rotation_to_quaternion(self.rotation_cam)

    def in_base(self, T_base_camera: Array) -> CubeDetection:
        R, p = T_base_camera[:3, :3], T_base_camera[:3, 3]
        return replace(self, centroid_base=R @ self.centroid_cam + p, rotation_base=R @ self.rotation_cam)


@dataclass(frozen=True)
class ObstacleBox:
    """Axis-aligned box around an obstacle, extruded down to the table (seed 004 BoxBounds)."""

    min_cam: Array
    max_cam: Array
    n_points: int
    color_label: str
    corners_px: Array  # (8, 2) projected corners of the base-frame box (camera-frame box without T)
    min_base: Array | None = None
    max_base: Array | None = None
    mean_rgb: Array | None = None
    visibility: Visibility = Visibility.WHOLE
    recognised: bool = True  # False: not the obstacle rule's kind, reported because it stands there

    def contains(self, points_base: Array) -> Array:
        if self.min_base is None or self.max_base is None:
            raise ValueError("obstacle box has no base-frame bounds (no T_base_camera given)")
        p = np.atleast_2d(points_base)
        return np.all((p >= self.min_base) & (p <= self.max_base), axis=1)


@dataclass(frozen=True)
class DetectionResult:
    rods: tuple[RodDetection, ...] = ()
    cubes: tuple[CubeDetection, ...] = ()
    obstacles: tuple[ObstacleBox, ...] = ()
    table: Plane | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    notes: tuple[str, ...] = ()  # why something was not detected or was rejected
    T_base_camera: Array | None = None
    stamp_ns: int = 0
    seq: int = 0

    @property
    def rod_detected(self) -> bool:
        return bool(self.rods)

    @property
    def best_rod(self) -> RodDetection | None:
        return self.rods[0] if self.rods else None
