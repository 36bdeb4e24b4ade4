"""One frame in, the objects on the table out: validation, table plane, rods, cubes, obstacles.

``VisionPipeline.detect`` is the pure core the vision service wraps: no I/O,
deterministic for a given frame (the RANSAC generator is seeded per call).
"""

from __future__ import annotations

import time
from dataclasses import replace

import cv2
import numpy as np
from threadpoolctl import ThreadpoolController

from services.common.errors import InvalidFrameError, InvalidInputError, VisionError
from services.common.frames import check_transform
from services.common.sensors import RGBDFrame
from services.common.settings import VisionSettings
from services.vision.cubes import detect_cubes_and_obstacles
from services.vision.geometry import Plane, backproject, fit_plane_ransac, scaled_stride
from services.vision.results import CubeDetection, DetectionResult, ObstacleBox, RodDetection
from services.vision.rod import detect_rods, heights_at

Array = np.ndarray

MIN_VALID_DEPTH_FRACTION = 0.05


def validate_frame(frame: RGBDFrame) -> Array:
    """Check shapes, types, intrinsics and depth content; return depth in metres (float32)."""
    if not isinstance(frame, RGBDFrame):
        raise InvalidFrameError(f"expected an RGBDFrame, got {type(frame).__name__}")
    try:
        frame.validate()
    except InvalidInputError as exc:
        raise InvalidFrameError(str(exc)) from exc
    if frame.depth.dtype.kind not in "uif":
        raise InvalidFrameError(f"depth image must be numeric, got dtype {frame.depth.dtype}")
    depth_m = frame.depth_m()
    valid = np.isfinite(depth_m) & (depth_m > 0)
    n_valid = int(np.count_nonzero(valid))
    if n_valid == 0:
        raise InvalidFrameError("depth image has no valid pixels (all zero or NaN): is the depth stream on?")
    if n_valid < MIN_VALID_DEPTH_FRACTION * depth_m.size:
        raise InvalidFrameError(
            f"depth image is {n_valid / depth_m.size:.1%} valid (< {MIN_VALID_DEPTH_FRACTION:.0%}): "
            "camera blocked or out of range"
        )
    if n_valid < depth_m.size:
        depth_m = np.where(valid, depth_m, np.float32(0.0))
    return depth_m


class VisionPipeline:
    """Table plane → rods (seed 001) and cubes/obstacles (seed 004) for one RGB-D frame."""

    def __init__(self, settings: VisionSettings | None = None, seed: int = 0):
        self.settings = settings or VisionSettings()
        self._seed = seed
        # The BLAS/OpenMP calls here are on N×3 arrays: a thread pool costs more than it gains and,
        # with other processes busy, its spinning threads made a 7 ms frame take ~30 ms. One thread.
        self._threads = ThreadpoolController()

    def detect(self, frame: RGBDFrame, T_base_camera: Array | None = None) -> DetectionResult:
        """Detect everything enabled in the settings; base-frame fields filled when T_base_camera is given.

        Nothing on the table is a normal result (empty lists, a note saying why), not an error.
        Raises InvalidFrameError for unusable frames and VisionError when no table plane is found.
        """
        with self._threads.limit(limits=1):
            return self._detect(frame, T_base_camera)

    def _detect(self, frame: RGBDFrame, T_base_camera: Array | None) -> DetectionResult:
        t_start = time.perf_counter()
        T = None if T_base_camera is None else check_transform(T_base_camera, "T_base_camera")
        depth_m = validate_frame(frame)
        s = self.settings
        intr = frame.intrinsics
        timings: dict[str, float] = {}
        notes: list[str] = []

        t0 = time.perf_counter()
        stride = scaled_stride(s.table.sample_stride, intr)
        cloud, _, _ = backproject(depth_m, intr, stride, None, s.cubes.min_depth_m, s.cubes.max_depth_m)
        if len(cloud) < 3:
            raise VisionError(
                f"no depth between {s.cubes.min_depth_m} and {s.cubes.max_depth_m} m: the table "
                "must lie in that range (vision.cubes.min_depth_m/max_depth_m)"
            )
        plane = fit_plane_ransac(
            cloud,
            s.table.ransac_threshold_m,
            s.table.iterations,
            np.random.default_rng(self._seed),
            s.table.max_ransac_points,
            s.table.min_inlier_fraction,
        )
        timings["plane"] = (time.perf_counter() - t0) * 1e3

        rods: list[RodDetection] = []
        if s.detect_rods:
            rods, rod_notes, rod_t = detect_rods(frame.color, depth_m, intr, plane, s.rod)
            timings.update(rod_t)
            notes += rod_notes
            if not rods:
                notes.insert(
                    0, "rod not detected: no dark, elongated region of the rod's size above the table"
                )
            if T is not None:
                rods = [r.in_base(T) for r in rods]

        cubes: list[CubeDetection] = []
        obstacles: list[ObstacleBox] = []
        if s.detect_cubes:
            exclude = _rod_footprint(rods, frame, depth_m, plane) if rods else None
            cubes, obstacles, cube_notes, cube_t = detect_cubes_and_obstacles(
                frame.color, depth_m, intr, plane, s.cubes, T, exclude
            )
            timings.update(cube_t)
            notes += cube_notes
            if not cubes:
                notes.append("no cubes detected")
        timings["total"] = (time.perf_counter() - t_start) * 1e3
        return DetectionResult(
            rods=tuple(rods),
            cubes=tuple(cubes),
            obstacles=tuple(obstacles),
            table=plane,
            timings_ms=timings,
            notes=tuple(notes),
            T_base_camera=T,
            stamp_ns=frame.stamp_ns,
            seq=frame.seq,
        )

    def with_settings(self, settings: VisionSettings) -> VisionPipeline:
        return VisionPipeline(settings, self._seed)


def _rod_footprint(rods: list[RodDetection], frame: RGBDFrame, depth_m: Array, plane: Plane) -> Array:
    """Pixels that show detected rods (near their image outline and no higher than a rod), so rod
    tops are not clustered as cubes while a taller object behind a rod keeps all its points."""
    mask = np.zeros(frame.depth.shape, np.uint8)
    f = frame.intrinsics.fx
    top = 0.0
    for rod in rods:
        width_px = int(np.ceil(f * rod.diameter_m * 1.6 / max(rod.center_cam[2], 1e-3))) + 4
        (u0, v0), (u1, v1) = np.rint(rod.endpoints_px).astype(int)
        cv2.line(mask, (int(u0), int(v0)), (int(u1), int(v1)), 1, thickness=width_px)
        top = max(top, rod.diameter_m)
    rows, cols = np.nonzero(mask)
    with np.errstate(invalid="ignore"):
        high = heights_at(depth_m, frame.intrinsics, plane, rows, cols) > top + 0.01
    mask[rows[high], cols[high]] = 0
    return mask.astype(bool)


def replace_timings(result: DetectionResult, **extra_ms: float) -> DetectionResult:
    """A copy of ``result`` with more stage timings (e.g. capture, measured by the service)."""
    return replace(result, timings_ms={**result.timings_ms, **extra_ms})
