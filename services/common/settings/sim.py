"""The simulated controller and its MuJoCo twin: physics, camera, scene."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from services.common.settings.base import (
    ALL_CUBE_COLORS,
    DEFAULT_DROP_ZONES_M,
    CubeColor,
    Model,
    Vec2,
    Vec3,
    is_loopback,
)


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
    cubes: list[CubeColor] = Field(default_factory=lambda: list(ALL_CUBE_COLORS))
    cube_size_m: float = Field(0.05, gt=0.01, le=0.08)
    cube_mass_kg: float = Field(0.075, gt=0, le=2)
    min_gap_m: float = Field(0.04, ge=0, le=0.3, description="clearance between objects for the fingers")
    drop_zones_m: dict[str, Vec2] = Field(default_factory=lambda: dict(DEFAULT_DROP_ZONES_M))
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


Range = tuple[float, float]


class TwinRandomizationSettings(Model):
    """Per-trial variation of the twin (``pickplace eval``; off for ``pickplace up``): each trial's world
    draws every value uniformly from its range, seeded from the trial's seed. What the cell is told stays
    nominal (vision's rod model, the calibration file, the camera's reported intrinsics), so every draw is
    an error the cell must measure or tolerate. Deltas are added to, scales multiply, the nominal value in
    ``physics`` / ``scene`` / ``camera``; absolute ranges replace it."""

    enabled: bool = False
    # Outer diameter: EN 10210-2 (hot-finished circular hollow sections), D ± 1 % with a minimum of
    # ± 0.5 mm, so 22 mm ± 0.5 mm (Tata Steel Blue Book, "Rolling tolerances to EN 10210-2").
    rod_diameter_delta_m: Range = (-0.0005, 0.0005)
    # Length: EN 10305-1 exact lengths L <= 0.5 m are 0 / +2 mm (Zelpo Steel Tube Handbook 2018, p. 62).
    rod_length_delta_m: Range = (0.0, 0.002)
    rod_mass_scale: Range = (0.8, 1.2)  # issue 19: +-20 % (wall thickness -10 % per EN 10210-2, fillings)
    # Finger pad on the rod: rubber / polyurethane pads on painted steel, static, dry; engineering-handbook
    # range for rubber on metal (no datasheet for our pads; Cutkosky & Wright 1986 on compliant pads).
    pad_friction: Range = (0.6, 1.2)
    # Rod on the table: steel on plastic 0.20-0.45, wood on steel 0.45-0.75 (static, dry; Lust CDA3000
    # engineering guide, table 7.21): painted steel on a laminate or wooden top.
    rod_table_friction: Range = (0.2, 0.75)
    table_height_delta_m: Range = (-0.005, 0.005)  # issue 19: table top vs. the robot base, +-5 mm
    grip_force_scale: Range = (0.8, 1.2)  # issue 19: +-20 % (supply pressure / current limit)
    # The drive's tracking: PD bandwidth +-25 % and a command latency of 0-2 servo ticks (8 ms, the
    # Dobot's 125 Hz loop). Assumption: no vendor figure for the Nova5's servo tuning.
    tracking_bandwidth_scale: Range = (0.75, 1.25)
    command_latency_s: Range = (0.0, 0.016)
    # Camera mount vs. the calibration the cell uses: +-2 mm per axis, +-0.5 deg about each axis (issue 19).
    camera_offset_m: Range = (-0.002, 0.002)
    camera_rotation_deg: Range = (-0.5, 0.5)
    # Intrinsics, true vs. reported (the factory calibration's residual): focal +-0.5 %, principal point
    # +-2 px. Assumption; for scale: a 1 deg FOV error is > 11 mm at 1 m (calvert.ch, "Improving the depth
    # map accuracy of RealSense cameras"), Intel's self-calibration white paper restores drifted units.
    focal_scale: Range = (0.995, 1.005)
    principal_offset_px: Range = (-2.0, 2.0)
    # Depth noise: subpixel RMS 0.05-0.15 px (Intel, "Tuning depth cameras for best performance": ~0.08
    # on good texture, worse on poor texture); depth holes on the black rod, share of its pixels.
    depth_subpixel: Range = (0.05, 0.15)
    hole_fraction: Range = (0.2, 0.5)
    # Light: key light and headlight intensity x scale; highlight strength on the specular rod (the
    # camera's highlight gain, 4 by default). Assumption: cell lighting from dim to bright.
    light_scale: Range = (0.6, 1.4)
    highlight_gain: Range = (2.0, 6.0)

    @model_validator(mode="after")
    def _ordered(self) -> TwinRandomizationSettings:
        for name in type(self).model_fields:
            v = getattr(self, name)
            if isinstance(v, tuple) and v[0] > v[1]:
                raise ValueError(f"randomization range {name} = {list(v)}: the low end is above the high end")
        for name in ("rod_mass_scale", "grip_force_scale", "tracking_bandwidth_scale", "focal_scale"):
            if getattr(self, name)[0] <= 0:
                raise ValueError(
                    f"randomization range {name} must stay above 0, got {list(getattr(self, name))}"
                )
        if self.command_latency_s[0] < 0 or self.command_latency_s[1] > 0.1:
            raise ValueError(
                f"command_latency_s must lie within 0..0.1 s, got {list(self.command_latency_s)}"
            )
        for name in ("pad_friction", "rod_table_friction", "depth_subpixel", "light_scale", "highlight_gain"):
            if getattr(self, name)[0] <= 0:
                raise ValueError(
                    f"randomization range {name} must stay above 0, got {list(getattr(self, name))}"
                )
        if not 0 <= self.hole_fraction[0] <= self.hole_fraction[1] <= 1:
            raise ValueError(f"hole_fraction must lie within 0..1, got {list(self.hole_fraction)}")
        return self


class TwinSettings(Model):
    """The MuJoCo physics twin of the cell (``services.sim.twin``)."""

    initial_joints_deg: tuple[float, float, float, float, float, float] = (0.0, 0.0, 90.0, 0.0, -90.0, 0.0)
    physics: TwinPhysicsSettings = TwinPhysicsSettings()
    camera: TwinCameraSettings = TwinCameraSettings()
    scene: TwinSceneSettings = TwinSceneSettings()
    # A ChArUco board (vision.calibration.board) on the gripper, for calibration runs in the twin.
    calibration_board: bool = False
    randomization: TwinRandomizationSettings = TwinRandomizationSettings()


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
    # ServoJ feed watchdog: a stream whose newest ServoJ is older than its t plus this margin is halted
    # (as a real controller ends a ServoJ whose t has run out). Host latency is wall time, so the
    # controller sees it ``speed`` times longer: the margin is scaled by the speed; null = off.
    servo_watchdog_margin_s: float | None = Field(0.5, gt=0, le=10)
    twin: TwinSettings = TwinSettings()

    @field_validator("host")
    @classmethod
    def _loopback(cls, v: str) -> str:
        if not is_loopback(v):
            raise ValueError(f"the simulated controller listens on loopback only, not {v!r}")
        return v
