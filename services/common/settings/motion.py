"""The motion service: planner, collision checking, Cartesian interpolation, the tool's shapes."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from services.common.settings.base import Model


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
