"""The vision service: camera source, table plane, rod and cube detectors, hand-eye calibration."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from services.common.settings.base import Model


class CameraSourceSettings(Model):
    """Which RGB-D source the vision service reads (RealSense D435i, the twin, or a replay directory)."""

    source: Literal["twin", "realsense", "replay", "bus"] = "bus"
    width: int = Field(640, ge=16, le=4096)
    height: int = Field(480, ge=16, le=4096)
    fps: int = Field(30, ge=1, le=90)
    serial: str = Field("", description="RealSense serial number; empty = the only attached camera")
    replay_dir: str | None = None
    replay_loop: bool = True


class TablePlaneSettings(Model):
    """RANSAC fit of the table plane to a strided depth cloud."""

    ransac_threshold_m: float = Field(0.008, gt=0, le=0.1)
    iterations: int = Field(128, ge=8, le=5000)
    sample_stride: int = Field(
        4, ge=1, le=32, description="cloud stride for the plane fit (px at 640 px width)"
    )
    max_ransac_points: int = Field(2000, ge=100)
    min_inlier_fraction: float = Field(0.2, gt=0, le=1)


class RodDetectionSettings(Model):
    """Seed 001 rod detector: dark HSV mask ∧ above-table mask, elongation test, cylinder fit."""

    length_m: float = Field(0.200, gt=0, le=2)
    diameter_m: float = Field(0.022, gt=0, le=0.2)
    length_tolerance: float = Field(0.25, gt=0, le=1, description="accepted relative length error")
    diameter_tolerance: float = Field(0.45, gt=0, le=1, description="accepted relative diameter error")
    dark_value_max: int = Field(70, ge=0, le=255, description="HSV value (0-255) at or below = dark")
    above_table_min_m: float = Field(0.004, ge=0, le=0.1)
    min_above_fraction: float = Field(
        0.5, ge=0, le=1, description="share of a candidate's depth pixels that must stand at rod height"
    )
    specular_chroma_max: int = Field(
        40, ge=0, le=255, description="max(R,G,B) - min(R,G,B) at or below = grey: a highlight on the metal"
    )
    max_taller_fraction: float = Field(
        0.3, gt=0, le=1, description="share of depth inside a fitted rod nearer than its surface = not a rod"
    )
    gap_close_fraction: float = Field(
        0.5, gt=0, le=2, description="closing element, as a share of the rod's expected width in pixels"
    )
    min_aspect_ratio: float = Field(3.0, ge=1)
    min_area_px: int = Field(120, ge=1, description="at 640 px width (scaled by width²)")
    min_depth_points: int = Field(40, ge=6, description="below this the pose comes from the silhouette")
    fit_loss_scale_m: float = Field(0.003, gt=0, le=0.05)
    max_rods: int = Field(5, ge=1, le=50)


class ObstacleRuleSettings(Model):
    """Seed 004: the obstacle is the (blue) cluster with ≥ 10000 points; made configurable."""

    color: Literal["blue", "red", "green", "black", "any"] = "blue"
    # Which size test makes a cluster "large": seed 004 counts points ("points"); a point count depends
    # on resolution and range, so the default measures the cluster's footprint instead.
    require: Literal["points", "extent", "either", "both"] = "extent"
    min_points: int = Field(10000, ge=1, description="pixels of a full 640-px-wide image")
    min_extent_m: float = Field(
        0.09, gt=0, description="longest side of the cluster's footprint on the table"
    )
    margin_m: float = Field(0.01, ge=0, le=0.5, description="added on every side of the obstacle box")


class ColorClassSettings(Model):
    """One named colour of the colour table: OpenCV hue ranges (0-179, [lo, hi)) of saturated pixels."""

    name: str = Field(min_length=1)
    hue_ranges: list[tuple[int, int]] = Field(min_length=1)

    @model_validator(mode="after")
    def _ranges(self) -> ColorClassSettings:
        for lo, hi in self.hue_ranges:
            if not 0 <= lo < hi <= 180:
                raise ValueError(f"colour {self.name!r}: hue range [{lo}, {hi}) must lie in [0, 180)")
        return self


DEFAULT_COLOR_TABLE: tuple[ColorClassSettings, ...] = (
    ColorClassSettings(name="red", hue_ranges=[(0, 10), (160, 180)]),
    ColorClassSettings(name="yellow", hue_ranges=[(20, 35)]),
    ColorClassSettings(name="green", hue_ranges=[(35, 90)]),
    ColorClassSettings(name="blue", hue_ranges=[(90, 135)]),
)


class CubeDetectionSettings(Model):
    """Seed 004 cube pipeline: depth thresholds, RANSAC plane, DBSCAN, colour labels."""

    min_depth_m: float = Field(0.2, ge=0)
    max_depth_m: float = Field(1.5, gt=0, le=10)
    plane_residual_m: float = Field(0.02, gt=0, le=0.2)
    max_height_m: float = Field(0.5, gt=0)
    dbscan_eps_m: float = Field(0.015, gt=0, le=0.2)
    dbscan_min_points: int = Field(40, ge=2, description="on a full 640-px-wide image; scaled by stride²")
    cluster_stride: int = Field(4, ge=1, le=8, description="cloud stride for DBSCAN (px at 640 px width)")
    min_cluster_points: int = Field(200, ge=1, description="pixels of a full 640-px-wide image")
    robot_base_radius_m: float = Field(
        0.13, ge=0, le=0.5, description="points this close to the robot's base axis are the robot itself"
    )
    cube_size_m: float = Field(0.05, gt=0, le=0.5)
    black_value_max: int = Field(70, ge=0, le=255, description="mean HSV value at or below = black")
    min_saturation: int = Field(60, ge=0, le=255, description="mean saturation below this = unlabelled")
    obstacle: ObstacleRuleSettings = ObstacleRuleSettings()
    colors: tuple[ColorClassSettings, ...] = Field(
        DEFAULT_COLOR_TABLE, description="colour table: black is value <= black_value_max, before these"
    )
    # Safety first: whatever stands on the table and is neither a cube nor a rod goes into the planning
    # scene as an obstacle box, whatever its colour or size (false = only the obstacle rule's boxes).
    unrecognised_as_obstacles: bool = True
    # Occlusion: a cube whose camera-facing surface is hidden by something nearer is fitted from the
    # faces that are seen; above this hidden share its centre is not trusted (an obstacle, not a target).
    occlusion_depth_margin_m: float = Field(
        0.01, gt=0, le=0.1, description="measured depth this much nearer than the fitted face = hidden"
    )
    occluded_max_fraction: float = Field(
        0.3, ge=0, le=1, description="hidden share of the visible faces above which a cube is not pickable"
    )

    @model_validator(mode="after")
    def _range(self) -> CubeDetectionSettings:
        if self.min_depth_m >= self.max_depth_m:
            raise ValueError(
                f"cube min_depth_m {self.min_depth_m} must be below max_depth_m {self.max_depth_m}"
            )
        return self


class CalibrationBoardSettings(Model):
    """The ChArUco board the gripper holds during hand-eye calibration."""

    squares_x: int = Field(5, ge=3, le=30)
    squares_y: int = Field(7, ge=3, le=30)
    square_length_m: float = Field(0.03, gt=0, le=0.5)
    marker_length_m: float = Field(0.022, gt=0, le=0.5)
    dictionary: str = "DICT_5X5_100"
    # Board origin in the gripper (tool) frame, only as a starting guess; the solve estimates it.
    T_gripper_board_guess: list[list[float]] | None = None

    @model_validator(mode="after")
    def _marker_fits(self) -> CalibrationBoardSettings:
        if self.marker_length_m >= self.square_length_m:
            raise ValueError(
                f"board marker_length_m {self.marker_length_m} must be smaller than "
                f"square_length_m {self.square_length_m}"
            )
        return self


class CalibrationSettings(Model):
    """Eye-to-hand calibration: where the result lives and how poses are generated."""

    file: str = "config/calibration.yaml"
    board: CalibrationBoardSettings = CalibrationBoardSettings()
    n_poses: int = Field(15, ge=3, le=200)
    # Safe volume (base frame, m) the board centre is moved through, and the tilt spread.
    volume_min: tuple[float, float, float] = (0.30, -0.20, 0.10)
    volume_max: tuple[float, float, float] = (0.55, 0.20, 0.30)
    max_tilt_deg: float = Field(25.0, ge=0, le=60)
    min_board_corners: int = Field(8, ge=4)
    max_reprojection_px: float = Field(2.0, gt=0)
    drift_warn_m: float = Field(0.005, gt=0)
    drift_warn_deg: float = Field(1.0, gt=0)
    # Manual (seed 001 PoC) camera pose in the base frame, used when no calibration file exists.
    manual_translation_m: tuple[float, float, float] | None = None
    manual_rpy_deg: tuple[float, float, float] | None = None

    @model_validator(mode="after")
    def _volume(self) -> CalibrationSettings:
        if any(lo >= hi for lo, hi in zip(self.volume_min, self.volume_max, strict=True)):
            raise ValueError(
                f"calibration volume_min {self.volume_min} must be below volume_max {self.volume_max}"
            )
        if (self.manual_translation_m is None) != (self.manual_rpy_deg is None):
            raise ValueError("give both calibration.manual_translation_m and manual_rpy_deg, or neither")
        return self


class VisionSettings(Model):
    camera: CameraSourceSettings = CameraSourceSettings()
    table: TablePlaneSettings = TablePlaneSettings()
    rod: RodDetectionSettings = RodDetectionSettings()
    cubes: CubeDetectionSettings = CubeDetectionSettings()
    calibration: CalibrationSettings = CalibrationSettings()
    detect_rods: bool = True
    detect_cubes: bool = True
    rate_hz: float = Field(5.0, ge=0.01, le=90, description="detections published per second at most")
    # the live loop (a detection rate_hz times a second for the dashboard) took the CPU a running
    # cycle's own detection and planning wait for: paused, a quiet 1x cycle's DETECT went from 0.44 to
    # 0.29 s and its PLAN from 0.62 to 0.34 s; each cycle's own detection is still published
    live_during_cycle: bool = Field(
        False, description="keep the live detection loop running while the task runs a cycle"
    )
    debug_jpeg_quality: int = Field(80, ge=10, le=100)
