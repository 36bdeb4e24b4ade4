"""The one validated settings model of pickplace.

Sources, lowest priority first: ``config/default.yaml``, then the selected
profile ``config/profiles/<profile>.yaml``, then an optional extra YAML file,
then ``PICKPLACE_*`` environment variables (nested with ``__``, e.g.
``PICKPLACE_ROBOT__SPEED_RATIO=30``). Unsafe values are rejected here, before
any service starts: a speed ratio outside 1–100, a non-loopback robot address
in the sim profile, Zenoh multicast scouting, non-loopback defaults.
"""

from __future__ import annotations

import ipaddress
import os
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, Field, SecretStr, ValidationError, field_validator, model_validator
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from services.common.errors import ConfigurationError

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_DIR = Path(os.environ.get("PICKPLACE_CONFIG_DIR", REPO_ROOT / "config"))
PROFILE_ENV = "PICKPLACE_PROFILE"
CONFIG_FILE_ENV = "PICKPLACE_CONFIG_FILE"

LOOPBACK_HOSTS = {"localhost", "ip6-localhost"}


def is_loopback(host: str) -> bool:
    if host in LOOPBACK_HOSTS:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def endpoint_host(endpoint: str) -> str:
    """Host part of a Zenoh endpoint such as ``tcp/127.0.0.1:7447`` or ``tcp/[::1]:7447``."""
    locator = endpoint.split("/", 1)[-1].split("#", 1)[0]
    host, _, _port = locator.rpartition(":")
    return host.strip("[]")


class Model(BaseModel):
    model_config = {"extra": "forbid", "validate_assignment": True}


class ReconnectSettings(Model):
    max_attempts: int = Field(5, ge=1, le=100)
    base_delay_s: float = Field(0.1, gt=0, le=10)
    max_delay_s: float = Field(2.0, gt=0, le=60)


class WorkspaceBounds(Model):
    """Axis-aligned box in the base frame (m) the tool tip must stay inside."""

    min: tuple[float, float, float] = (-0.85, -0.85, 0.0)
    max: tuple[float, float, float] = (0.85, 0.85, 1.2)

    @model_validator(mode="after")
    def _ordered(self) -> WorkspaceBounds:
        if any(lo >= hi for lo, hi in zip(self.min, self.max, strict=True)):
            raise ValueError(f"workspace min {self.min} must be below max {self.max} on every axis")
        return self


class RobotSettings(Model):
    model: Literal["nova5", "ur5e", "ur3"] = "nova5"
    host: str = "127.0.0.1"
    dashboard_port: int = Field(29999, ge=1, le=65535)
    feedback_port: int = Field(30004, ge=1, le=65535)
    speed_ratio: int = Field(50, description="global SpeedFactor, percent")
    acc_ratio: int = Field(50, ge=1, le=100)
    request_timeout_s: float = Field(2.0, gt=0, le=60)
    connect_timeout_s: float = Field(2.0, gt=0, le=60)
    feedback_timeout_s: float = Field(1.0, gt=0, le=60)
    motion_timeout_s: float = Field(60.0, gt=0, le=3600)
    step_retries: int = Field(2, ge=0, le=10)
    retry_wait_s: float = Field(0.5, ge=0, le=10)
    servo_period_s: float = Field(0.03, ge=0.004, le=1.0)
    servo_lookahead: int = Field(4, ge=1, le=100, description="ServoJ targets queued ahead of execution")
    reconnect: ReconnectSettings = ReconnectSettings()
    workspace: WorkspaceBounds = WorkspaceBounds()
    # Cap on joint speed the driver accepts in a trajectory, as a fraction of the model's limit.
    max_velocity_scale: float = Field(1.0, gt=0, le=1.0)
    allow_remote: bool = Field(
        False, description="a non-loopback robot address is only accepted when this is true"
    )

    @field_validator("speed_ratio")
    @classmethod
    def _speed_ratio(cls, v: int) -> int:
        if not 1 <= v <= 100:
            raise ValueError(f"speed_ratio must be within 1-100 percent, got {v}")
        return v

    @model_validator(mode="after")
    def _remote(self) -> RobotSettings:
        if not is_loopback(self.host) and not self.allow_remote:
            raise ValueError(
                f"robot host {self.host!r} is not a loopback address; select the 'nova5-real' "
                "profile (robot.allow_remote: true) to drive a real robot"
            )
        return self


class GripperSettings(Model):
    """Parallel-jaw gripper on controller digital outputs."""

    close_do: int = Field(1, ge=1, le=1000, description="DO index that closes the jaws when ON")
    open_do: int | None = Field(2, ge=1, le=1000, description="DO that opens (None: close_do OFF opens)")
    tool_outputs: bool = Field(False, description="use the flange ToolDO instead of the cabinet DO")
    actuation_time_s: float = Field(0.4, ge=0, le=10)
    object_di: int | None = Field(None, ge=1, le=1000, description="DI that reads 1 when holding")
    stroke_m: float = Field(0.085, gt=0, le=0.3)
    # Flange → grasp centre (between the pads) along the flange z axis; shared by motion and the twin.
    tcp_offset_m: float = Field(0.16, gt=0, le=0.5)


Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
CubeColor = Literal["red", "blue", "green", "black"]


class TwinPhysicsSettings(Model):
    """Contact and solver settings of the physics twin, in one place.

    Why each value: ``shared/specs/twin-physics-notes.md``. impratio >= 10 (or noslip) stops the
    rod creeping in the grasp during the 90 deg turn; elliptic cones; condim-4 pads with friction
    about 1; a grip of >= 3 N per finger; multi-contact CCD stays on (MuJoCo's default).
    """

    timestep_s: float = Field(0.002, gt=0, le=0.01)
    impratio: float = Field(10.0, ge=1, le=100)
    noslip_iterations: int = Field(0, ge=0, le=100)
    cone: Literal["elliptic", "pyramidal"] = "elliptic"
    pad_friction: float = Field(1.0, gt=0, le=3)
    pad_torsional_friction_m: float = Field(0.005, ge=0, le=0.1)
    object_friction: float = Field(0.6, gt=0, le=3)
    table_friction: float = Field(0.6, gt=0, le=3)
    grip_force_n: float = Field(10.0, ge=1, le=200, description="squeeze force per finger")
    finger_speed_m_s: float = Field(0.1, gt=0, le=1, description="closing speed of each finger")
    collision_force_n: float = Field(20.0, gt=0, description="arm contact force that raises alarm 117")
    tracking_bandwidth_rad_s: float = Field(40.0, gt=1, le=200, description="arm PD natural frequency")

    @model_validator(mode="after")
    def _cone(self) -> TwinPhysicsSettings:
        if self.cone == "pyramidal" and self.noslip_iterations == 0:
            raise ValueError(
                "cone 'pyramidal' lets the rod slip in the grasp; use it with noslip_iterations > 0"
            )
        return self


class TwinCameraSettings(Model):
    """The simulated RealSense D435i colour stream (depth aligned to it) and its noise model."""

    width: int = Field(640, ge=16, le=1920)
    height: int = Field(480, ge=16, le=1080)
    fovy_deg: float = Field(42.5, gt=1, lt=170)
    position_m: Vec3 = (0.93, 0.0, 0.66)  # base frame; ~0.8 m from the pick zone, ~55 deg down
    look_at_m: Vec3 = (0.475, 0.0, 0.0)
    min_depth_m: float = Field(0.15, ge=0)
    max_depth_m: float = Field(4.0, gt=0)
    noise: bool = True
    depth_subpixel: float = Field(0.08, ge=0, description="stereo disparity noise, px (sigma_z ~ z^2)")
    stereo_baseline_m: float = Field(0.05, gt=0)
    stereo_focal_px: float = Field(383.0, gt=0)
    hole_objects: list[str] = Field(default_factory=lambda: ["rod"], description="black/shiny: lose depth")
    hole_fraction: float = Field(0.35, ge=0, le=1)
    flying_pixel_fraction: float = Field(0.5, ge=0, le=1)
    edge_dropout_fraction: float = Field(0.2, ge=0, le=1)
    rgb_noise_sigma: float = Field(2.0, ge=0, le=50)

    @model_validator(mode="after")
    def _pose(self) -> TwinCameraSettings:
        if sum((a - b) ** 2 for a, b in zip(self.position_m, self.look_at_m, strict=True)) < 1e-6:
            raise ValueError("camera position_m and look_at_m must differ")
        if self.max_depth_m <= self.min_depth_m:
            raise ValueError(
                f"camera max_depth_m {self.max_depth_m} must exceed min_depth_m {self.min_depth_m}"
            )
        return self


class TwinSceneSettings(Model):
    """Cell layout (robot base frame, table top at z = 0) and the seeded objects on it."""

    pick_zone_min_m: Vec2 = (0.35, -0.25)
    pick_zone_max_m: Vec2 = (0.60, 0.25)
    rod: bool = True
    rod_length_m: float = Field(0.20, gt=0.02, le=0.5)
    rod_diameter_m: float = Field(0.022, gt=0.004, le=0.08)
    rod_wall_m: float = Field(0.002, gt=0, le=0.04)
    rod_mass_kg: float = Field(0.10, gt=0, le=2)
    cubes: list[CubeColor] = Field(default_factory=lambda: ["red", "blue", "green", "black"])
    cube_size_m: float = Field(0.05, gt=0.01, le=0.08)
    cube_mass_kg: float = Field(0.075, gt=0, le=2)
    min_gap_m: float = Field(0.04, ge=0, le=0.3, description="clearance between objects for the fingers")
    drop_zones_m: dict[str, Vec2] = Field(
        default_factory=lambda: {
            "red": (0.30, 0.45),
            "blue": (0.45, 0.45),
            "green": (0.30, -0.45),
            "black": (0.45, -0.45),
        }
    )
    rod_place_m: Vec2 = (0.45, 0.0)
    obstacle: bool = True
    # A wall between the pick zone and the red/blue drop zones (seed 004: plan over it, not around).
    obstacle_center_m: Vec3 = (0.40, 0.34, 0.06)
    obstacle_half_size_m: Vec3 = (0.10, 0.025, 0.06)

    @model_validator(mode="after")
    def _zones(self) -> TwinSceneSettings:
        if any(lo >= hi for lo, hi in zip(self.pick_zone_min_m, self.pick_zone_max_m, strict=True)):
            raise ValueError(f"pick zone min {self.pick_zone_min_m} must be below max {self.pick_zone_max_m}")
        if self.rod_wall_m * 2 > self.rod_diameter_m:
            raise ValueError(f"rod wall {self.rod_wall_m} m is thicker than the rod radius")
        missing = sorted(set(self.cubes) - set(self.drop_zones_m))
        if missing:
            raise ValueError(f"cubes {missing} have no drop zone in drop_zones_m")
        if len(set(self.cubes)) != len(self.cubes):
            raise ValueError(f"cube colours must be unique, got {self.cubes}")
        return self


class TwinSettings(Model):
    """The MuJoCo physics twin of the cell (``services.sim.twin``)."""

    initial_joints_deg: tuple[float, float, float, float, float, float] = (0.0, 0.0, 90.0, 0.0, -90.0, 0.0)
    physics: TwinPhysicsSettings = TwinPhysicsSettings()
    camera: TwinCameraSettings = TwinCameraSettings()
    scene: TwinSceneSettings = TwinSceneSettings()
    # A ChArUco board (vision.calibration.board) on the gripper, for calibration runs in the twin.
    calibration_board: bool = False


class SimSettings(Model):
    host: str = "127.0.0.1"
    dashboard_port: int = Field(29999, ge=0, le=65535)
    feedback_port: int = Field(30004, ge=0, le=65535)
    slow_feedback_port: int = Field(30005, ge=0, le=65535)
    feedback_period_s: float = Field(0.008, gt=0, le=1)
    slow_feedback_period_s: float = Field(0.2, gt=0, le=10)
    engine: Literal["kinematic", "twin"] = "kinematic"
    speed: float = Field(1.0, gt=0, description="sim time / wall time; >1 runs faster")
    seed: int = 0
    # Joint speed and acceleration of the simulated controller at 100 % (deg/s, deg/s^2).
    max_joint_speed_deg_s: float = Field(180.0, gt=0)
    max_joint_acc_deg_s2: float = Field(720.0, gt=0)
    twin: TwinSettings = TwinSettings()

    @field_validator("host")
    @classmethod
    def _loopback(cls, v: str) -> str:
        if not is_loopback(v):
            raise ValueError(f"the simulated controller listens on loopback only, not {v!r}")
        return v


class ZenohSettings(Model):
    mode: Literal["peer", "client", "router"] = "peer"
    listen: list[str] = Field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    connect: list[str] = Field(default_factory=list)
    multicast_scouting: bool = False
    allow_remote: bool = False

    @model_validator(mode="after")
    def _safe(self) -> ZenohSettings:
        if self.multicast_scouting:
            raise ValueError("zenoh multicast scouting must stay off; give explicit endpoints")
        if not self.allow_remote:
            for ep in [*self.listen, *self.connect]:
                if not is_loopback(endpoint_host(ep)):
                    raise ValueError(f"zenoh endpoint {ep!r} is not loopback (set zenoh.allow_remote)")
        return self


class GrpcSettings(Model):
    host: str = "127.0.0.1"
    robot_port: int = Field(50051, ge=0, le=65535)
    motion_port: int = Field(50052, ge=0, le=65535)
    vision_port: int = Field(50053, ge=0, le=65535)
    grasp_port: int = Field(50054, ge=0, le=65535)
    task_port: int = Field(50055, ge=0, le=65535)
    request_timeout_s: float = Field(10.0, gt=0)
    # Where clients dial each service when it runs elsewhere (a compose/Kubernetes service name);
    # None = ``host``. The service itself always binds ``host``.
    robot_host: str | None = None
    motion_host: str | None = None
    vision_host: str | None = None
    grasp_host: str | None = None
    task_host: str | None = None

    def client_host(self, service: Literal["robot", "motion", "vision", "grasp", "task"]) -> str:
        """The address clients use for ``service``: its own host if set, else the shared bind host."""
        return getattr(self, f"{service}_host") or self.host


class MetricsSettings(Model):
    """A per-process Prometheus exporter (``/metrics``) for services without an HTTP server of their own.

    None = off (``pickplace up`` and the gateway serve metrics themselves). Deployments set
    ``PICKPLACE_METRICS__PORT`` (and ``PROMETHEUS_MULTIPROC_DIR``) per container.
    """

    host: str = "127.0.0.1"
    port: int | None = Field(None, ge=0, le=65535)
    allow_remote: bool = Field(False, description="a non-loopback bind address needs this")

    @model_validator(mode="after")
    def _loopback(self) -> MetricsSettings:
        if not self.allow_remote and not is_loopback(self.host):
            raise ValueError(f"metrics host {self.host!r} is not loopback (set metrics.allow_remote)")
        return self


class LoggingSettings(Model):
    level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    file: str | None = "var/log/pickplace.log"
    max_bytes: int = 10 * 1024 * 1024
    backups: int = 5


class KeyPoseCycleSettings(Model):
    """The demonstration cycle of seed 003 (joint key poses in degrees)."""

    poses_deg: dict[str, tuple[float, float, float, float, float, float]] = Field(
        default_factory=lambda: {
            "home": (0.0, 0.0, 90.0, 0.0, -90.0, 0.0),
            "pre_grasp": (30.0, 20.0, 80.0, -10.0, -90.0, 0.0),
            "grasp": (30.0, 30.0, 80.0, -20.0, -90.0, 0.0),
            "lift": (30.0, 20.0, 80.0, -10.0, -90.0, 0.0),
            "transport": (-30.0, 20.0, 80.0, -10.0, -90.0, 0.0),
            "place": (-30.0, 30.0, 80.0, -20.0, -90.0, 0.0),
            "retreat": (-30.0, 20.0, 80.0, -10.0, -90.0, 0.0),
        }
    )
    sequence: list[str] = Field(
        default_factory=lambda: [
            "home",
            "pre_grasp",
            "grasp",
            "lift",
            "transport",
            "place",
            "retreat",
            "home",
        ]
    )
    move_duration_s: float = Field(2.0, gt=0)
    dwell_s: float = Field(0.5, ge=0)
    max_step_deg: float = Field(5.0, gt=0, le=90)

    @model_validator(mode="after")
    def _known(self) -> KeyPoseCycleSettings:
        unknown = [n for n in self.sequence if n not in self.poses_deg]
        if unknown:
            raise ValueError(f"key-pose sequence names unknown poses {unknown}")
        return self


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
    cube_size_m: float = Field(0.05, gt=0, le=0.5)
    black_value_max: int = Field(70, ge=0, le=255, description="mean HSV value at or below = black")
    min_saturation: int = Field(60, ge=0, le=255, description="mean saturation below this = unlabelled")
    obstacle: ObstacleRuleSettings = ObstacleRuleSettings()

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
    rate_hz: float = Field(5.0, gt=0, le=90, description="detections published per second at most")
    debug_jpeg_quality: int = Field(80, ge=10, le=100)


class ToolSettings(Model):
    """The gripper's collision shapes on the flange (flange frame, m / deg). The TCP sits
    ``gripper.tcp_offset_m`` along the flange z axis (one value for motion, grasp and twin),
    turned by ``tip_rpy_deg``."""

    tip_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    palm_radius_m: float = Field(0.045, gt=0, le=0.3)
    palm_length_m: float = Field(0.09, ge=0, le=0.5)
    finger_box_m: tuple[float, float, float] = (0.03, 0.12, 0.04)
    finger_clearance_m: float = Field(
        0.015, ge=0, le=0.1, description="jaw tips left out of collision checks"
    )


class MotionSettings(Model):
    """Motion service: planner, collision checking, Cartesian interpolation, timing."""

    planner: Literal["RRTConnect", "RRTstar", "PRM"] = "RRTConnect"
    planning_time_s: float = Field(1.0, gt=0, le=60, description="budget per planning request")
    collision_resolution_deg: float = Field(1.0, gt=0, le=10, description="joint step between checked states")
    velocity_scale: float = Field(1.0, gt=0, le=1.0, description="fraction of the model's joint limits")
    acceleration_scale: float = Field(1.0, gt=0, le=1.0)
    knot_period_s: float = Field(0.01, ge=0.001, le=0.1, description="time between trajectory knots")
    cartesian_step_m: float = Field(0.005, gt=0, le=0.1)
    cartesian_step_deg: float = Field(2.0, gt=0, le=30)
    jump_threshold_deg: float = Field(
        10.0, gt=0, le=180, description="largest joint change per Cartesian step"
    )
    min_manipulability: float = Field(1e-3, ge=0, description="IK solutions below this count as singular")
    table_z_m: float = 0.0
    padding_m: float = Field(0.01, ge=0, le=0.2, description="clearance kept from the table and boxes")
    box_y_extension_m: float = Field(0.0, ge=0, le=2.0, description="seed 004: stretch boxes along ±y")
    seed: int = 0
    tool: ToolSettings = ToolSettings()


class DatabaseSettings(Model):
    """The gateway's SQL database: pick history, system health, calibrations (LLD §8.2).

    SQLite (aiosqlite) is the embedded default; PostgreSQL through asyncpg in deployments
    (``DATABASE_URL=postgresql+asyncpg://…`` or ``PICKPLACE_DATABASE__URL``).
    """

    url: str = "sqlite+aiosqlite:///var/pickplace.db"
    schema_name: str | None = Field(
        None, pattern=r"^[a-z_][a-z0-9_]{0,62}$", description="PostgreSQL schema (search_path); None = public"
    )
    auto_migrate: bool = Field(False, description="upgrade to the newest revision at start (embedded run)")
    pool_size: int = Field(5, ge=1, le=100)
    connect_timeout_s: float = Field(5.0, gt=0, le=60)
    command_timeout_s: float = Field(10.0, gt=0, le=300)

    @field_validator("url")
    @classmethod
    def _driver(cls, v: str) -> str:
        if not v.startswith(("sqlite+aiosqlite://", "postgresql+asyncpg://")):
            scheme = v.split("://", 1)[0] if "://" in v else v[:20]
            raise ValueError(
                f"database url must use sqlite+aiosqlite:// or postgresql+asyncpg://, got {scheme!r}"
            )
        return v


class GatewaySettings(Model):
    """REST API, live updates, dashboard, Prometheus metrics and the authenticated gRPC edge."""

    host: str = "127.0.0.1"
    port: int = Field(8080, ge=0, le=65535)
    allow_remote: bool = Field(False, description="a non-loopback bind address needs this")
    # Bearer token for mutating requests. No default anywhere: PICKPLACE_GATEWAY__API_TOKEN, or the
    # embedded local run generates one and prints it.
    api_token: SecretStr | None = None
    cors_origins: list[str] = Field(default_factory=list, description="empty = CORS closed")
    max_request_bytes: int = Field(65536, ge=1024, le=16 * 1024 * 1024)
    joint_state_rate_hz: float = Field(20.0, gt=0, le=125, description="joint states sent to browsers")
    robot_status_period_s: float = Field(0.5, ge=0.05, le=60)
    health_period_s: float = Field(10.0, ge=0.1, le=3600)
    robot_id: str = Field("robot_01", pattern=r"^[A-Za-z0-9_\-]{1,50}$")
    pick_buffer_size: int = Field(
        1000, ge=1, le=1_000_000, description="picks held in memory while the DB is down"
    )
    pick_spill_file: str = Field("var/gateway/pick_spill.jsonl", description="overflow of that buffer")
    pick_batch_size: int = Field(100, ge=1, le=10_000)
    db_retry_initial_s: float = Field(0.2, gt=0, le=60)
    db_retry_max_s: float = Field(5.0, gt=0, le=600)
    rpc_timeout_s: float = Field(3.0, gt=0, le=60, description="start/stop relay to the task service")
    estop_timeout_s: float = Field(1.0, gt=0, le=10)
    edge_grpc_port: int | None = Field(
        50060, ge=0, le=65535, description="authenticated gRPC edge; None = off"
    )
    web_dir: str = "web"

    @field_validator("api_token")
    @classmethod
    def _token_strength(cls, v: SecretStr | None) -> SecretStr | None:
        if v is not None and len(v.get_secret_value()) < 16:
            raise ValueError(f"api_token must be at least 16 characters, got {len(v.get_secret_value())}")
        return v

    @model_validator(mode="after")
    def _bind(self) -> GatewaySettings:
        if not self.allow_remote and not is_loopback(self.host):
            raise ValueError(f"gateway host {self.host!r} is not loopback (set gateway.allow_remote)")
        if "*" in self.cors_origins:
            raise ValueError("gateway.cors_origins must list origins; '*' is refused")
        return self


Vec6 = tuple[float, float, float, float, float, float]


class GraspGripperSettings(Model):
    """Jaw geometry for grasp synthesis, in the tool frame (tool z = approach, jaws close along tool y).

    Defaults are the twin's gripper (``services/sim/twin/mjcf.py``): 22 × 20 mm pads centred on the
    TCP, fingertips 10 mm beyond it; the stroke and the TCP offset are ``gripper.*``.
    """

    pad_length_m: float = Field(0.022, gt=0, le=0.2, description="pad extent along tool x")
    pad_height_m: float = Field(
        0.020, gt=0, le=0.2, description="pad extent along tool z, centred on the TCP"
    )
    finger_thickness_m: float = Field(0.014, gt=0, le=0.1, description="pad + finger, along tool y")
    fingertip_beyond_tcp_m: float = Field(0.010, ge=0, le=0.2)
    finger_length_m: float = Field(0.08, gt=0, le=0.5, description="palm bottom to fingertip")
    palm_half_xy_m: Vec2 = (0.035, 0.06)
    palm_height_m: float = Field(0.07, gt=0, le=0.5, description="palm box above the fingers")
    width_margin_m: float = Field(0.01, ge=0, le=0.1, description="opening kept beyond the object width")
    min_width_m: float = Field(0.004, ge=0, le=0.2)
    table_clearance_m: float = Field(0.002, ge=0, le=0.05, description="fingertips above the table")
    grip_force_n: float = Field(10.0, gt=0, le=500, description="target squeeze per finger")


class ForceClosureSettings(Model):
    """LLD §10.3: contact model of the Ferrari–Canny metric."""

    friction_coefficient: float = Field(0.5, gt=0, le=3, description="LLD default 0.5")
    cone_edges: int = Field(8, ge=3, le=32, description="friction-cone polyhedral approximation")
    torsional_friction_m: float = Field(0.005, ge=0, le=0.1, description="soft-finger torque per newton")
    points_per_line: int = Field(2, ge=2, le=8, description="point contacts modelling a line contact")


class RodStandSettings(Model):
    """Seed 001 §3.5 pick-and-stand; numbers from ``shared/specs/twin-physics-notes.md``."""

    place_xy_m: Vec2 | None = Field((0.45, 0.0), description="rod base on the table; None = where it lay")
    grasp_offset_m: float = Field(
        0.0, ge=-0.2, le=0.2, description="grasp point along the rod from its centre"
    )
    offset_tolerance_m: float = Field(
        0.03, ge=0, le=0.2, description="worst grasp offset error along the rod"
    )
    min_lift_m: float = Field(
        0.15, gt=0, le=0.6, description="the notes: 0.10 strikes the table, 0.15 clears"
    )
    turn_clearance_m: float = Field(0.02, ge=0, le=0.2, description="lowest rod point above the table")
    place_approach_m: float = Field(
        0.04, gt=0, le=0.3, description="rod base above the table before the guard"
    )
    carry_raise_m: float = Field(
        0.08, ge=0, le=0.5, description="carry this much above PLACE_ABOVE (clear cubes)"
    )
    guard_overtravel_m: float = Field(0.01, ge=0, le=0.05, description="descent allowed past nominal touch")
    guard_speed_m_s: float = Field(0.025, gt=0, le=0.2)
    touch_force_drop_n: float = Field(0.6, gt=0, le=50, description="wrist force drop that means touch-down")
    retreat_m: float = Field(0.05, gt=0, le=0.3, description="back out along the approach after release")
    retract_up_m: float = Field(0.10, ge=0, le=0.5)
    retract_clear_m: float = Field(
        0.06,
        ge=0,
        le=0.3,
        description="tool tip at least this far above the standing rod's top after the retract (the palm hangs "
        "below the tip)",
    )
    max_axis_tilt_deg: float = Field(20.0, ge=0, le=60, description="a lying rod's axis this far from level")
    max_height_error_m: float = Field(0.03, ge=0, le=0.2, description="rod centre vs table + radius")
    heading_step_deg: float = Field(30.0, ge=5, le=180, description="tool headings tried after the turn")
    turn_step_deg: float = Field(
        4.0, gt=0, le=10, description="orientation step of the turn checks (motion executes it densely)"
    )

    @model_validator(mode="after")
    def _guard_starts_above(self) -> RodStandSettings:
        if self.place_approach_m <= self.offset_tolerance_m:
            raise ValueError(
                f"rod place_approach_m {self.place_approach_m} must exceed offset_tolerance_m "
                f"{self.offset_tolerance_m}: a rod grasped off-centre would touch down before the guard starts"
            )
        return self


class CubeSortSettings(Model):
    """Seed 004: cubes go to colour-keyed drop zones (base frame, table top at z = 0)."""

    drop_zones_m: dict[str, Vec2] = Field(
        default_factory=lambda: {
            "red": (0.30, 0.45),
            "blue": (0.45, 0.45),
            "green": (0.30, -0.45),
            "black": (0.45, -0.45),
        }
    )
    transport_height_m: float = Field(
        0.25, gt=0, le=1.0, description="tool tip while carrying (over obstacles)"
    )
    place_clearance_m: float = Field(
        0.005, ge=0, le=0.1, description="cube bottom above the table at release"
    )
    place_approach_m: float = Field(0.05, gt=0, le=0.3)
    guard_overtravel_m: float = Field(0.005, ge=0, le=0.05)
    guard_speed_m_s: float = Field(0.03, gt=0, le=0.2)
    touch_force_drop_n: float = Field(0.4, gt=0, le=50)
    retract_up_m: float = Field(0.10, ge=0, le=0.5)
    max_approach_tilt_deg: float = Field(10.0, ge=0, le=90, description="cube grasps: near top-down only")


class GraspSettings(Model):
    """Grasp service: synthesis, quality, reachability and the task-level waypoint plans."""

    gripper: GraspGripperSettings = GraspGripperSettings()
    force_closure: ForceClosureSettings = ForceClosureSettings()
    rod: RodStandSettings = RodStandSettings()
    cubes: CubeSortSettings = CubeSortSettings()
    num_candidates: int = Field(20, ge=1, le=500, description="LLD §4.2 num_candidates")
    approach_distance_m: float = Field(0.10, gt=0, le=0.5, description="pre-grasp offset along the approach")
    lift_m: float = Field(0.10, gt=0, le=0.5, description="lift after a (non-rod) grasp")
    max_grasp_depth_m: float = Field(0.06, gt=0, le=0.3, description="TCP below the entry face")
    table_z_m: float = 0.0
    jump_threshold_deg: float = Field(10.0, gt=0, le=90, description="largest joint step on a dense path")
    path_step_m: float = Field(
        0.01, gt=0, le=0.05, description="sampling of straight tool lines in the IK checks"
    )
    min_singularity_deg: float = Field(3.0, ge=0, le=45, description="|sin q5|, |sin q3| kept above this")
    arm_table_clearance_m: float = Field(
        0.08, ge=0, le=0.5, description="elbow and wrist joints above the table"
    )
    safe_home_joints_deg: dict[str, Vec6] = Field(
        default_factory=lambda: {
            "nova5": (180.0, 0.0, 90.0, 0.0, -90.0, 0.0),
            "ur5e": (180.0, -90.0, 90.0, -90.0, -90.0, 0.0),
            "ur3": (180.0, -90.0, 60.0, -60.0, -90.0, 0.0),
        },
        description="SAFE_HOME per robot model: above the workspace, tool down",
    )


class TaskSettings(Model):
    """The task orchestrator: which job, retries (LLD §15.2) and per-state deadlines."""

    task: Literal["stand-rod", "sort-cubes"] = "stand-rod"
    detect_retries: int = Field(4, ge=0, le=20)  # waits 0.5, 1, 2, 4 s (doubling)
    detect_retry_delay_s: float = Field(0.5, ge=0, le=30)
    grasp_alternatives: int = Field(
        8,
        ge=1,
        le=48,
        description="plans tried per cycle (rod: 7 grasp points along it, then the next wrist option)",
    )
    alarm_recoveries: int = Field(2, ge=0, le=10)
    regrasps: int = Field(2, ge=0, le=10)
    verify_grasp: bool = True
    detect_deadline_s: float = Field(10.0, gt=0)
    plan_deadline_s: float = Field(30.0, gt=0)
    motion_deadline_s: float = Field(60.0, gt=0)
    gripper_deadline_s: float = Field(10.0, gt=0)
    status_rate_hz: float = Field(2.0, gt=0, le=50)
    pause_between_cycles_s: float = Field(0.5, ge=0, le=60)
    # Fractions of the joint speed/acceleration limits while carrying the object and on guarded moves.
    holding_speed_scale: float = Field(0.4, gt=0, le=1)
    guarded_speed_scale: float = Field(0.1, gt=0, le=1)
    # A fresh twin scene after each cycle in `pickplace up` (the simulated operator lays the rod down again).
    reset_scene_each_cycle: bool = True


class Settings(BaseSettings):
    model_config = SettingsConfigDict(
        env_prefix="PICKPLACE_", env_nested_delimiter="__", extra="forbid", validate_assignment=True
    )

    profile: str = "sim"
    cell_id: str = Field("cell1", pattern=r"^[A-Za-z0-9_\-]+$")
    robot: RobotSettings = RobotSettings()
    gripper: GripperSettings = GripperSettings()
    sim: SimSettings = SimSettings()
    zenoh: ZenohSettings = ZenohSettings()
    grpc: GrpcSettings = GrpcSettings()
    logging: LoggingSettings = LoggingSettings()
    cycle: KeyPoseCycleSettings = KeyPoseCycleSettings()
    motion: MotionSettings = MotionSettings()
    vision: VisionSettings = VisionSettings()
    grasp: GraspSettings = GraspSettings()
    database: DatabaseSettings = DatabaseSettings()
    gateway: GatewaySettings = GatewaySettings()
    task: TaskSettings = TaskSettings()
    metrics: MetricsSettings = MetricsSettings()

    @model_validator(mode="after")
    def _profile_safety(self) -> Settings:
        if self.profile == "sim" and not is_loopback(self.robot.host):
            raise ValueError(f"the sim profile must not name a robot address ({self.robot.host!r})")
        return self

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        # Explicit arguments win, then environment, then the YAML layers passed as init kwargs
        # by load_settings (they arrive through _YamlSource).
        return (init_settings, env_settings, _YamlSource(settings_cls))


_yaml_layers: list[dict[str, Any]] = []


class _YamlSource(PydanticBaseSettingsSource):
    def get_field_value(self, field: Any, field_name: str) -> tuple[Any, str, bool]:  # pragma: no cover
        return None, field_name, False

    def __call__(self) -> dict[str, Any]:
        merged: dict[str, Any] = {}
        for layer in _yaml_layers:
            merged = deep_merge(merged, layer)
        return merged


def deep_merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def read_yaml(path: Path) -> dict[str, Any]:
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except FileNotFoundError as exc:
        raise ConfigurationError(f"config file not found: {path}") from exc
    except yaml.YAMLError as exc:
        raise ConfigurationError(f"config file {path} is not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigurationError(f"config file {path} must hold a mapping, not {type(data).__name__}")
    return data


def load_settings(
    profile: str | None = None,
    config_file: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    config_dir: Path | None = None,
) -> Settings:
    """Build the validated settings; raise ConfigurationError naming every bad field."""
    cdir = config_dir or CONFIG_DIR
    profile = profile or os.environ.get(PROFILE_ENV) or "sim"
    layers = [read_yaml(cdir / "default.yaml")]
    profile_path = cdir / "profiles" / f"{profile}.yaml"
    if not profile_path.exists():
        known = sorted(p.stem for p in (cdir / "profiles").glob("*.yaml"))
        raise ConfigurationError(f"unknown profile {profile!r}; known profiles: {known}")
    layers.append(read_yaml(profile_path))
    extra = config_file or os.environ.get(CONFIG_FILE_ENV)
    if extra:
        layers.append(read_yaml(Path(extra)))
    layers.append({"profile": profile})
    if overrides:
        layers.append(overrides)
    global _yaml_layers
    _yaml_layers = layers
    try:
        return Settings()
    except ValidationError as exc:
        raise ConfigurationError(format_validation_error(exc)) from exc
    finally:
        _yaml_layers = []


def format_validation_error(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "settings"
        parts.append(f"{loc}: {err['msg']}")
    return "invalid configuration: " + "; ".join(parts)
