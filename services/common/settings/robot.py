"""The robot link (Dobot controller address, timeouts, retries, workspace) and the key-pose demo cycle."""

from __future__ import annotations

from enum import StrEnum
from typing import Literal

from pydantic import Field, field_validator, model_validator

from services.common.settings.base import Model, is_loopback


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


class RobotDriverKind(StrEnum):
    """The protocol the driver speaks to the controller."""

    DOBOT = "dobot"  # Dobot V4 TCP/IP (dashboard 29999, feedback 30004)
    UR_RTDE = "ur_rtde"  # a Universal Robots controller through SDU's ur_rtde (RTDE 30004, 500 Hz)


class RobotSettings(Model):
    model: Literal["nova5", "ur5e", "ur3"] = "nova5"
    driver: RobotDriverKind = RobotDriverKind.DOBOT
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
    # ServoJ targets kept queued ahead of the one executing (0.3 s at 30 ms): what the host may stall for
    # without the controller running dry. At 4 (0.12 s) the host fell behind and a stream was resumed from
    # rest (a 0.5-1 s ramp) 3 times in 20 twin trials at 1x on a quiet machine, 5 times beside 6 busy
    # processes; at 10, never. Stops and touch-downs are not held up by it: Stop halts the queue. A stream
    # that continues into the next keeps 12 (services.robot.driver.CONTINUE_TARGETS).
    servo_lookahead: int = Field(10, ge=1, le=100, description="ServoJ targets queued ahead of execution")
    reconnect: ReconnectSettings = ReconnectSettings()
    workspace: WorkspaceBounds = WorkspaceBounds()
    # Execution monitoring: measured joints against the plan during every motion (path) and at its
    # end (goal, reached within goal_settle_s of controller time); beyond either the arm is stopped.
    path_tolerance_rad: float = Field(0.05, gt=0, le=1.0)
    goal_tolerance_rad: float = Field(0.005, gt=0, le=0.5)
    goal_settle_s: float = Field(0.5, ge=0, le=10)
    # ServoJ feed watchdog: a stream the host still owes targets is stopped once the controller has run
    # dry for a period plus this long (controller and host clocks both)
    servo_watchdog_margin_s: float = Field(0.25, gt=0, le=10)
    # The nice value of the process the driver runs in: `pickplace serve robot` alone, or the whole cell in
    # one (`pickplace up`, `pickplace eval`; `up --processes` starts its services from it). Below 0 its
    # e-stop, its streams, and the replies and frames the arm waits for are scheduled before other work
    # on a busy machine (services.common.priority; needs CAP_SYS_NICE, refused: a warning); null = as is
    process_nice: int | None = Field(None, ge=-20, le=19)
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
    def _driver_fits_model(self) -> RobotSettings:
        if self.driver is RobotDriverKind.UR_RTDE and self.model not in ("ur5e", "ur3"):
            raise ValueError(f"robot.driver ur_rtde drives a UR (ur5e, ur3), not robot.model {self.model!r}")
        return self

    @model_validator(mode="after")
    def _remote(self) -> RobotSettings:
        if not is_loopback(self.host) and not self.allow_remote:
            raise ValueError(
                f"robot host {self.host!r} is not a loopback address; select the 'nova5-real' "
                "profile (robot.allow_remote: true) to drive a real robot"
            )
        return self


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
