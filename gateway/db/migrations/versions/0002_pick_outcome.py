"""picks.outcome: running | succeeded | failed | interrupted (a row per started cycle, issue 13).

Rows stored before it were all finished picks: their outcome follows ``success``.

Revision ID: 0002_pick_outcome
Revises: 0001_initial
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002_pick_outcome"
down_revision = "0001_initial"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("picks") as batch:
        batch.add_column(sa.Column("outcome", sa.String(16), nullable=False, server_default="failed"))
    op.execute("UPDATE picks SET outcome = CASE WHEN success THEN 'succeeded' ELSE 'failed' END")
    op.create_index("idx_picks_outcome", "picks", ["outcome"])


def downgrade() -> None:
    op.drop_index("idx_picks_outcome", table_name="picks")
    with op.batch_alter_table("picks") as batch:
        batch.drop_column("outcome")
