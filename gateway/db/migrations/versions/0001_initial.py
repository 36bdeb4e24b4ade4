"""LLD §8.2 tables: picks (with the task's outcome fields), system_health, calibrations.

Revision ID: 0001_initial
Revises:
Create Date: 2026-11-01
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects.postgresql import JSONB

revision = "0001_initial"
down_revision = None
branch_labels = None
depends_on = None

ID = sa.BigInteger().with_variant(sa.Integer(), "sqlite")
JSON = sa.JSON().with_variant(JSONB(), "postgresql")
TS = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "picks",
        sa.Column("id", ID, primary_key=True, autoincrement=True),
        sa.Column("pick_id", sa.String(64), nullable=False),
        sa.Column("timestamp", TS, nullable=False),
        sa.Column("robot_id", sa.String(50), nullable=False),
        sa.Column("object_id", sa.String(100)),
        sa.Column("object_class", sa.String(50)),
        sa.Column("pick_pose", JSON),
        sa.Column("place_pose", JSON),
        sa.Column("grasp_quality", sa.Float()),
        sa.Column("cycle_time", sa.Float()),
        sa.Column("success", sa.Boolean(), nullable=False),
        sa.Column("error_code", sa.String(100)),
        sa.Column("error_message", sa.Text()),
        sa.Column("task", sa.String(32)),
        sa.Column("stage_reached", sa.String(32)),
        sa.Column("stage_durations", JSON),
        sa.Column("attempts", sa.Integer()),
        sa.UniqueConstraint("pick_id", name="uq_picks_pick_id"),
    )
    # (timestamp DESC, id DESC): the history's order, so a page is an index range and deep pages skip in the index
    op.create_index("idx_picks_timestamp", "picks", [sa.text("timestamp DESC"), sa.text("id DESC")])
    op.create_index("idx_picks_robot_id", "picks", ["robot_id"])
    op.create_index("idx_picks_success", "picks", ["success"])

    op.create_table(
        "system_health",
        sa.Column("id", ID, primary_key=True, autoincrement=True),
        sa.Column("timestamp", TS, nullable=False),
        sa.Column("robot_id", sa.String(50), nullable=False),
        sa.Column("cpu_percent", sa.Float()),
        sa.Column("memory_percent", sa.Float()),
        sa.Column("disk_percent", sa.Float()),
        sa.Column("gpu_percent", sa.Float()),
        sa.Column("gpu_memory_mb", sa.Float()),
        sa.Column("temperature_celsius", sa.Float()),
    )
    op.create_index("idx_system_health_timestamp", "system_health", [sa.text("timestamp DESC")])

    op.create_table(
        "calibrations",
        sa.Column("id", ID, primary_key=True, autoincrement=True),
        sa.Column("run_id", sa.String(32), nullable=False),
        sa.Column("timestamp", TS, nullable=False),
        sa.Column("robot_id", sa.String(50), nullable=False),
        sa.Column("calibration_type", sa.String(50), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("num_poses", sa.Integer()),
        sa.Column("parameters", JSON),
        sa.Column("reprojection_error", sa.Float()),
        sa.Column("notes", sa.Text()),
        sa.UniqueConstraint("run_id", name="uq_calibrations_run_id"),
    )
    op.create_index("idx_calibrations_timestamp", "calibrations", [sa.text("timestamp DESC")])


def downgrade() -> None:
    op.drop_index("idx_calibrations_timestamp", table_name="calibrations")
    op.drop_table("calibrations")
    op.drop_index("idx_system_health_timestamp", table_name="system_health")
    op.drop_table("system_health")
    op.drop_index("idx_picks_success", table_name="picks")
    op.drop_index("idx_picks_robot_id", table_name="picks")
    op.drop_index("idx_picks_timestamp", table_name="picks")
    op.drop_table("picks")
