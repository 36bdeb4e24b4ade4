"""SQLAlchemy 2 models of the LLD §8.2 operational tables, plus the task issue's per-pick outcome.

Poses and parameters are JSON (JSONB on PostgreSQL). Timestamps are timezone-aware UTC.
``picks.pick_id`` is the task's idempotency key: a pick event is stored once however often
it arrives. The failure reason of a pick goes to the LLD's ``error_message`` column.
``picks.outcome`` is where the pick's record stands (:class:`PickState`): a row is written when
its cycle starts (running), updated as it goes, and fixed at its first outcome (:data:`PICK_STATE_RANK`).
"""

from __future__ import annotations

import enum
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    Index,
    Integer,
    String,
    Text,
    UniqueConstraint,
    text,
)
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

# SQLite only autoincrements an INTEGER PRIMARY KEY; PostgreSQL gets a BIGINT identity.
IdType = BigInteger().with_variant(Integer(), "sqlite")
JsonType = JSON().with_variant(JSONB(), "postgresql")


def utcnow() -> datetime:
    return datetime.now(UTC)


class PickState(enum.StrEnum):
    RUNNING = "running"  # the cycle started and has not ended (or the gateway has not heard yet)
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    INTERRUPTED = "interrupted"  # a crash (or an operator's stop) cut the cycle at stage_reached


# A row only moves forward: from running to interrupted to the cycle's own outcome, and the first outcome
# stored is the one kept (a duplicate, or an "interrupted" sent again after the task had reported the end,
# changes nothing). "Interrupted" ranks below the outcome the cycle itself reports: it is what the gateway
# or a restarted task concludes when it has not heard, and the cycle's own word may still be on its way
# (a newer cycle's start can reach the gateway before the older cycle's outcome on the other key).
PICK_STATE_RANK = {
    PickState.RUNNING: 0,
    PickState.INTERRUPTED: 1,
    PickState.SUCCEEDED: 2,
    PickState.FAILED: 2,
}
REPORTED_OUTCOMES = (PickState.SUCCEEDED, PickState.FAILED)


class Base(DeclarativeBase):
    pass


class Pick(Base):
    __tablename__ = "picks"

    id: Mapped[int] = mapped_column(IdType, primary_key=True, autoincrement=True)
    pick_id: Mapped[str] = mapped_column(String(64), nullable=False)
    timestamp: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    robot_id: Mapped[str] = mapped_column(String(50), nullable=False)
    object_id: Mapped[str | None] = mapped_column(String(100))
    object_class: Mapped[str | None] = mapped_column(String(50))
    pick_pose: Mapped[dict[str, Any] | None] = mapped_column(JsonType)
    place_pose: Mapped[dict[str, Any] | None] = mapped_column(JsonType)
    grasp_quality: Mapped[float | None] = mapped_column(Float)
    cycle_time: Mapped[float | None] = mapped_column(Float)  # s
    success: Mapped[bool] = mapped_column(Boolean, nullable=False)
    error_code: Mapped[str | None] = mapped_column(String(100))
    error_message: Mapped[str | None] = mapped_column(Text)
    # the task issue's outcome fields
    task: Mapped[str | None] = mapped_column(String(32))
    stage_reached: Mapped[str | None] = mapped_column(String(32))
    stage_durations: Mapped[dict[str, float] | None] = mapped_column(JsonType)  # state -> s
    attempts: Mapped[int | None] = mapped_column(Integer)
    outcome: Mapped[str] = mapped_column(String(16), nullable=False, server_default=PickState.FAILED.value)

    __table_args__ = (
        UniqueConstraint("pick_id", name="uq_picks_pick_id"),
        Index("idx_picks_timestamp", text("timestamp DESC"), text("id DESC")),
        Index("idx_picks_robot_id", "robot_id"),
        Index("idx_picks_success", "success"),
        Index("idx_picks_outcome", "outcome"),
    )


class SystemHealth(Base):
    __tablename__ = "system_health"

    id: Mapped[int] = mapped_column(IdType, primary_key=True, autoincrement=True)
    timestamp: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    robot_id: Mapped[str] = mapped_column(String(50), nullable=False)
    cpu_percent: Mapped[float | None] = mapped_column(Float)
    memory_percent: Mapped[float | None] = mapped_column(Float)
    disk_percent: Mapped[float | None] = mapped_column(Float)
    gpu_percent: Mapped[float | None] = mapped_column(Float)
    gpu_memory_mb: Mapped[float | None] = mapped_column(Float)
    temperature_celsius: Mapped[float | None] = mapped_column(Float)

    __table_args__ = (Index("idx_system_health_timestamp", text("timestamp DESC")),)


class Calibration(Base):
    __tablename__ = "calibrations"

    id: Mapped[int] = mapped_column(IdType, primary_key=True, autoincrement=True)
    run_id: Mapped[str] = mapped_column(String(32), nullable=False)
    timestamp: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    robot_id: Mapped[str] = mapped_column(String(50), nullable=False)
    calibration_type: Mapped[str] = mapped_column(String(50), nullable=False)  # hand_eye | tcp | workspace
    status: Mapped[str] = mapped_column(String(16), nullable=False)  # running | succeeded | failed
    num_poses: Mapped[int | None] = mapped_column(Integer)
    parameters: Mapped[dict[str, Any] | None] = mapped_column(JsonType)
    reprojection_error: Mapped[float | None] = mapped_column(Float)
    notes: Mapped[str | None] = mapped_column(Text)

    __table_args__ = (
        UniqueConstraint("run_id", name="uq_calibrations_run_id"),
        Index("idx_calibrations_timestamp", text("timestamp DESC")),
    )
