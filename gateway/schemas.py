"""REST models (LLD §13.1). Pydantic at the edge; the proto messages stay inside."""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from gateway.contract import JsonInt
from gateway.db.models import PickState
from services.common.modes import TaskKind


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class CommandResult(BaseModel):
    success: bool
    message: str = ""


class EstopResult(CommandResult):
    latency_ms: float = Field(description="REST request received → robot driver confirmed the e-stop")


class TaskSummary(BaseModel):
    state: str
    message: str = ""
    progress: float = 0.0
    picks_completed: int = 0
    picks_failed: int = 0
    average_cycle_time: float = 0.0
    task: str = ""
    running: bool = False
    cycle_index: int = 0
    last_error: str = ""
    age_s: float | None = Field(None, description="seconds since the task service last reported")


class RobotSummary(BaseModel):
    connected: bool = False
    robot_mode: int | None = None
    robot_mode_name: str | None = None
    enabled: bool | None = None
    estop_active: bool | None = None
    alarms: list[int] = []
    gripper_closed: bool | None = None
    robot_model: str | None = None
    error: str | None = None


class HealthSummary(BaseModel):
    timestamp: datetime
    cpu_percent: float | None = None
    memory_percent: float | None = None
    disk_percent: float | None = None
    gpu_percent: float | None = None
    gpu_memory_mb: float | None = None
    temperature_celsius: float | None = None


class SystemStatus(BaseModel):
    """LLD: {"state", "uptime", "picks_today"} plus success rate, the task's and the robot's state."""

    state: str
    uptime: float = Field(description="gateway uptime, s")
    picks_today: int
    success_rate: float | None
    task: TaskSummary | None = None
    robot: RobotSummary
    database: Literal["ok", "unavailable"]
    pick_buffer: int = Field(description="pick events waiting to be written")
    health: HealthSummary | None = None


class StartRequest(Strict):
    task: TaskKind = TaskKind.STAND_ROD
    cycles: JsonInt = Field(0, ge=0, le=100_000, description="0 = until stopped")


class PoseJson(BaseModel):
    x: float
    y: float
    z: float
    qx: float
    qy: float
    qz: float
    qw: float


class PickRecord(BaseModel):
    """One row of the history (LLD PickRecord + the task's outcome fields)."""

    model_config = ConfigDict(from_attributes=True)

    id: int
    pick_id: str
    timestamp: datetime
    robot_id: str
    object_id: str | None = None
    object_class: str | None = None
    cycle_time: float | None = None
    success: bool
    outcome: PickState = Field(
        description="succeeded, failed, or interrupted (a crash or a stop cut the cycle at stage_reached)",
    )
    grasp_quality: float | None = None
    error_code: str | None = None
    error_message: str | None = None
    task: str | None = None
    stage_reached: str | None = None
    attempts: int | None = None


class PickDetail(PickRecord):
    pick_pose: PoseJson | None = None
    place_pose: PoseJson | None = None
    stage_durations: dict[str, float] | None = None


class MetricsSummary(BaseModel):
    """LLD: {success_rate, avg_cycle_time, uptime}, plus counts and cycle-time percentiles."""

    success_rate: float | None
    avg_cycle_time: float | None = Field(description="mean cycle time of successful picks, s")
    uptime: float
    picks_total: int
    picks_succeeded: int
    picks_failed: int
    picks_today: int
    cycle_time_p50: float | None
    cycle_time_p95: float | None


class CalibrationRequest(Strict):
    num_poses: JsonInt = Field(15, ge=3, le=200)


class CalibrationStarted(BaseModel):
    calibration_id: str


class CalibrationStatus(StrEnum):
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


class CalibrationView(BaseModel):
    calibration_id: str
    status: CalibrationStatus
    progress: float = Field(description="[0, 1]")
    message: str = ""
    num_poses: int | None = None
    started_at: datetime
    reprojection_error: float | None = None
    parameters: dict[str, Any] | None = None


class ConfigUpdateResult(BaseModel):
    success: bool
    updated: list[str]
    applied_now: list[str] = []  # in effect as the services receive the update (well under a second)
    applied_next_cycle: list[str] = []  # taken at the next key-pose cycle / twin scene
    note: str = "changes last until the cell restarts; keep them in a config file or profile"


class CameraInfo(BaseModel):
    """The camera as the dashboard's 3D view draws it: its pinhole and its pose in the base frame."""

    width: int = Field(description="image width, px")
    height: int = Field(description="image height, px")
    fx: float
    fy: float
    cx: float
    cy: float
    T_base_camera: list[list[float]] | None = Field(
        description="4×4, camera optical frame (x right, y down, z forward) → base frame, metres; "
        "null when the cell has neither a calibration file nor a manual pose"
    )
    pose_source: str = Field(description="where the pose comes from (the calibration file, the manual pose)")
