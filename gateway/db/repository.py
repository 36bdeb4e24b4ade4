"""Queries on the operational tables. Sessions are passed in; nothing here opens connections."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np
from sqlalchemy import case, delete, func, select
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.ext.asyncio import AsyncSession

from gateway.db.models import Calibration, Pick, SystemHealth

# Percentiles of the cycle time are taken over this many newest successful picks.
CYCLE_STATS_WINDOW = 1000


@dataclass(frozen=True)
class PickSummary:
    total: int
    succeeded: int
    failed: int
    success_rate: float | None
    avg_cycle_time_s: float | None
    p50_cycle_time_s: float | None
    p95_cycle_time_s: float | None
    picks_today: int


def start_of_day_utc(now: datetime) -> datetime:
    now = now.astimezone(UTC)
    return now.replace(hour=0, minute=0, second=0, microsecond=0)


async def insert_picks(session: AsyncSession, rows: Sequence[dict[str, Any]]) -> list[tuple[int, str]]:
    """Insert pick rows, skipping pick_ids already stored; return (id, pick_id) of the new rows.

    Idempotent: the same batch inserted twice stores each pick once. The caller commits.
    """
    unique: dict[str, dict[str, Any]] = {}
    for r in rows:
        unique.setdefault(r["pick_id"], r)
    if not unique:
        return []
    dialect = session.bind.dialect.name if session.bind is not None else "sqlite"
    insert = postgresql.insert if dialect == "postgresql" else sqlite.insert
    stmt = (
        insert(Pick)
        .values(list(unique.values()))
        .on_conflict_do_nothing(index_elements=[Pick.pick_id])
        .returning(Pick.id, Pick.pick_id)
    )
    result = await session.execute(stmt)
    return [(int(i), str(p)) for i, p in result.all()]


class PickRepository:
    def __init__(self, session: AsyncSession):
        self.session = session

    @staticmethod
    def _filters(success: bool | None, robot_id: str | None) -> list[Any]:
        conds: list[Any] = []
        if success is not None:
            conds.append(Pick.success.is_(success))
        if robot_id is not None:
            conds.append(Pick.robot_id == robot_id)
        return conds

    def _page_ids(self, limit: int, offset: int, success: bool | None, robot_id: str | None) -> Any:
        # Deferred join: find the page's ids first (skipping ``offset`` entries of the index, not whole
        # rows), then fetch only those rows.
        return (
            select(Pick.id)
            .where(*self._filters(success, robot_id))
            .order_by(Pick.timestamp.desc(), Pick.id.desc())
            .limit(limit)
            .offset(offset)
            .subquery()
        )

    async def page(
        self, limit: int, offset: int, success: bool | None = None, robot_id: str | None = None
    ) -> list[Pick]:
        """Newest first, as ORM rows with every column."""
        ids = self._page_ids(limit, offset, success, robot_id)
        stmt = select(Pick).join(ids, Pick.id == ids.c.id).order_by(Pick.timestamp.desc(), Pick.id.desc())
        return list((await self.session.scalars(stmt)).all())

    async def page_rows(
        self,
        columns: Sequence[str],
        limit: int,
        offset: int,
        success: bool | None = None,
        robot_id: str | None = None,
    ) -> list[dict[str, Any]]:
        """Newest first, only ``columns``, as plain dicts (the history list: no ORM objects, no JSON columns)."""
        ids = self._page_ids(limit, offset, success, robot_id)
        table = Pick.__table__
        stmt = (
            select(*(table.c[c] for c in columns))
            .join(ids, table.c.id == ids.c.id)
            .order_by(table.c.timestamp.desc(), table.c.id.desc())
        )
        return [dict(r) for r in (await self.session.execute(stmt)).mappings().all()]

    async def count(self, success: bool | None = None, robot_id: str | None = None) -> int:
        stmt = select(func.count()).select_from(Pick).where(*self._filters(success, robot_id))
        return int((await self.session.scalar(stmt)) or 0)

    async def get(self, pick_db_id: int) -> Pick | None:
        return await self.session.get(Pick, pick_db_id)

    async def picks_today(self, now: datetime) -> int:
        stmt = select(func.count()).select_from(Pick).where(Pick.timestamp >= start_of_day_utc(now))
        return int((await self.session.scalar(stmt)) or 0)

    async def today(self, now: datetime) -> tuple[int, int]:
        """(picks, successful picks) since midnight UTC."""
        total, ok = (
            await self.session.execute(
                select(func.count(), func.coalesce(func.sum(case((Pick.success.is_(True), 1), else_=0)), 0))
                .select_from(Pick)
                .where(Pick.timestamp >= start_of_day_utc(now))
            )
        ).one()
        return int(total), int(ok)

    async def summary(self, now: datetime) -> PickSummary:
        total, succeeded, avg = (
            await self.session.execute(
                select(
                    func.count(),
                    func.coalesce(func.sum(case((Pick.success.is_(True), 1), else_=0)), 0),
                    func.avg(Pick.cycle_time).filter(Pick.success.is_(True)),
                ).select_from(Pick)
            )
        ).one()
        recent = (
            await self.session.scalars(
                select(Pick.cycle_time)
                .where(Pick.success.is_(True), Pick.cycle_time.is_not(None))
                .order_by(Pick.timestamp.desc())
                .limit(CYCLE_STATS_WINDOW)
            )
        ).all()
        times = np.asarray([t for t in recent if t is not None], dtype=float)
        total, succeeded = int(total), int(succeeded)
        return PickSummary(
            total=total,
            succeeded=succeeded,
            failed=total - succeeded,
            success_rate=(succeeded / total) if total else None,
            avg_cycle_time_s=float(avg) if avg is not None else None,
            p50_cycle_time_s=float(np.percentile(times, 50)) if times.size else None,
            p95_cycle_time_s=float(np.percentile(times, 95)) if times.size else None,
            picks_today=await self.picks_today(now),
        )


class HealthRepository:
    def __init__(self, session: AsyncSession):
        self.session = session

    async def add(self, robot_id: str, sample: dict[str, float | None], at: datetime) -> None:
        self.session.add(SystemHealth(robot_id=robot_id, timestamp=at, **sample))

    async def latest(self) -> SystemHealth | None:
        return await self.session.scalar(
            select(SystemHealth).order_by(SystemHealth.timestamp.desc()).limit(1)
        )

    async def prune(self, older_than: timedelta, now: datetime) -> None:
        await self.session.execute(delete(SystemHealth).where(SystemHealth.timestamp < now - older_than))


class CalibrationRepository:
    def __init__(self, session: AsyncSession):
        self.session = session

    async def by_run_id(self, run_id: str) -> Calibration | None:
        return await self.session.scalar(select(Calibration).where(Calibration.run_id == run_id))

    async def latest(self, calibration_type: str = "hand_eye") -> Calibration | None:
        return await self.session.scalar(
            select(Calibration)
            .where(Calibration.calibration_type == calibration_type)
            .order_by(Calibration.timestamp.desc())
            .limit(1)
        )
