"""Queries on the operational tables. Sessions are passed in; nothing here opens connections."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np
from sqlalchemy import and_, case, delete, func, literal, or_, select, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.ext.asyncio import AsyncSession

from gateway.db.models import PICK_STATE_RANK, REPORTED_OUTCOMES, Calibration, Pick, PickState, SystemHealth
from services.common.errors import CycleInterruptedError

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


# Columns an event for a pick already stored brings up to date. A value the newer event lacks (NULL)
# keeps the stored one: an "interrupted" sent by a restarted task never erases what the cycle had found.
_UPDATED = (
    "object_id",
    "object_class",
    "pick_pose",
    "place_pose",
    "grasp_quality",
    "cycle_time",
    "error_code",
    "error_message",
    "task",
    "stage_reached",
    "stage_durations",
    "attempts",
)
_ENDED = Pick.outcome != PickState.RUNNING.value  # the statistics count picks that ended
# what an outcome the cycle reports itself takes as it is, over an "interrupted" concluded before it
_ERROR = ("error_code", "error_message")


def _rank(outcome: Any) -> Any:
    return case(*((outcome == s.value, r) for s, r in PICK_STATE_RANK.items()), else_=0)


def _forward(stored: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """Two events of one pick in one batch, merged as the database would (see :func:`insert_picks`)."""
    old_rank, new_rank = (
        PICK_STATE_RANK[PickState(stored["outcome"])],
        PICK_STATE_RANK[PickState(new["outcome"])],
    )
    if new_rank < old_rank or (new_rank == old_rank and old_rank > 0):
        return stored
    reported = PickState(new["outcome"]) in REPORTED_OUTCOMES
    merged = {
        k: (stored.get(k) if v is None and not (reported and k in _ERROR) else v) for k, v in new.items()
    }
    merged["timestamp"], merged["robot_id"] = stored["timestamp"], stored["robot_id"]
    return merged


async def insert_picks(session: AsyncSession, rows: Sequence[dict[str, Any]]) -> list[tuple[int, str]]:
    """Store pick rows: a new ``pick_id`` is inserted, a stored one brought forward, never back.

    A cycle's row is written when it starts (outcome running), updated with each stage it reaches,
    and fixed at its first outcome (succeeded, failed, interrupted; the cycle's own succeeded or failed
    still replaces an interrupted concluded before it came): the same event stored twice, or an older
    one after a newer, changes nothing. Any row of a robot's newer cycle marks that robot's
    older rows still running as interrupted (a task that crashed and came back without saying so:
    one robot runs one cycle at a time). Returns ``(id, pick_id)`` of the rows that reached their
    outcome with this call, so each finished pick is reported once. The caller commits.
    """
    merged: dict[str, dict[str, Any]] = {}
    for r in rows:
        r = {"outcome": (PickState.SUCCEEDED if r["success"] else PickState.FAILED).value, **r}
        merged[r["pick_id"]] = _forward(merged[r["pick_id"]], r) if r["pick_id"] in merged else r
    if not merged:
        return []
    dialect = session.bind.dialect.name if session.bind is not None else "sqlite"
    insert = postgresql.insert if dialect == "postgresql" else sqlite.insert
    table = Pick.__table__
    values = insert(Pick).values(list(merged.values()))
    new = values.excluded
    stmt = values.on_conflict_do_update(
        index_elements=[Pick.pick_id],
        set_={
            **{c: func.coalesce(new[c], table.c[c]) for c in _UPDATED if c not in _ERROR},
            **{
                c: case(
                    (new.outcome.in_([o.value for o in REPORTED_OUTCOMES]), new[c]),
                    else_=func.coalesce(new[c], table.c[c]),
                )
                for c in _ERROR
            },
            "success": new.success,
            "outcome": new.outcome,
        },
        where=or_(
            _rank(table.c.outcome) < _rank(new.outcome),
            and_(table.c.outcome == PickState.RUNNING.value, new.outcome == PickState.RUNNING.value),
        ),
    ).returning(Pick.id, Pick.pick_id, Pick.robot_id, Pick.outcome)
    result = (await session.execute(stmt)).all()
    newest: dict[str, int] = {}
    for i, _p, robot, _o in result:
        newest[robot] = max(newest.get(robot, 0), int(i))
    for robot, newest_id in newest.items():
        await session.execute(
            update(Pick)
            .where(Pick.robot_id == robot, Pick.outcome == PickState.RUNNING.value, Pick.id < newest_id)
            .values(
                outcome=PickState.INTERRUPTED.value,
                success=False,
                error_code=CycleInterruptedError.__name__,
                error_message=func.coalesce(Pick.stage_reached, "INIT")
                + literal(": interrupted: a later cycle of this robot started before this one ended"),
            )
        )
    return [(int(i), str(p)) for i, p, _r, o in result if o != PickState.RUNNING.value]


class PickRepository:
    def __init__(self, session: AsyncSession):
        self.session = session

    @staticmethod
    def _filters(success: bool | None, robot_id: str | None) -> list[Any]:
        # the history lists picks that ended: a cycle in progress has its row, listed once it ends
        conds: list[Any] = [_ENDED]
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
        stmt = select(func.count()).select_from(Pick).where(Pick.timestamp >= start_of_day_utc(now), _ENDED)
        return int((await self.session.scalar(stmt)) or 0)

    async def today(self, now: datetime) -> tuple[int, int]:
        """(picks, successful picks) since midnight UTC."""
        total, ok = (
            await self.session.execute(
                select(func.count(), func.coalesce(func.sum(case((Pick.success.is_(True), 1), else_=0)), 0))
                .select_from(Pick)
                .where(Pick.timestamp >= start_of_day_utc(now), _ENDED)
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
                )
                .select_from(Pick)
                .where(_ENDED)
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
