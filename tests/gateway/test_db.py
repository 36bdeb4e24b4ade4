"""Migrations up and down on SQLite and PostgreSQL; models and migrations agree; idempotent inserts."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import inspect

from gateway.convert import pick_row
from gateway.db import migrate
from gateway.db.engine import database_url, make_engine, session_factory
from gateway.db.models import Base
from gateway.db.repository import PickRepository, insert_picks, start_of_day_utc
from services.common.errors import ConfigurationError
from services.common.settings import DatabaseSettings
from tests.gateway.conftest import pick_event

TABLES = {"picks", "system_health", "calibrations"}


async def _tables(engine) -> set[str]:  # type: ignore[no-untyped-def]
    async with engine.connect() as conn:
        return set(await conn.run_sync(lambda c: inspect(c).get_table_names())) - {"alembic_version"}


async def test_upgrade_downgrade_roundtrip(database: DatabaseSettings):
    engine = make_engine(database, database.url)
    try:
        with pytest.raises(ConfigurationError, match=r"never migrated.*pickplace db upgrade"):
            await migrate.require_head(engine, "db")
        assert await migrate.upgrade(engine, database) == migrate.head_revision()
        assert await _tables(engine) == TABLES
        await migrate.require_head(engine, "db")  # no error now
        async with engine.connect() as conn:
            indexes = await conn.run_sync(lambda c: {i["name"] for i in inspect(c).get_indexes("picks")})
        assert {"idx_picks_timestamp", "idx_picks_robot_id", "idx_picks_success"} <= indexes

        assert await migrate.downgrade(engine, "base") is None
        assert await _tables(engine) == set()
        with pytest.raises(ConfigurationError, match="never migrated"):
            await migrate.require_head(engine, "db")
        # and up again on the emptied database
        assert await migrate.upgrade(engine, database) == migrate.head_revision()
    finally:
        await engine.dispose()


async def test_migration_matches_models_on_postgres(postgres_db: DatabaseSettings):
    engine = make_engine(postgres_db, postgres_db.url)
    try:
        await migrate.upgrade(engine, postgres_db)
        async with engine.connect() as conn:
            diff = await conn.run_sync(
                lambda c: compare_metadata(
                    MigrationContext.configure(c, opts={"compare_type": True}), Base.metadata
                )
            )
        assert diff == [], f"models and migrations disagree: {diff}"
    finally:
        await engine.dispose()


async def test_insert_is_idempotent_and_pages(database: DatabaseSettings):
    engine = make_engine(database, database.url)
    try:
        await migrate.upgrade(engine, database)
        sessions = session_factory(engine)
        t0 = datetime(2026, 1, 1, tzinfo=UTC)
        events = [
            pick_event(i, success=i % 3 != 0, stamp_ns=int((t0 + timedelta(seconds=i)).timestamp() * 1e9))
            for i in range(25)
        ]
        rows = [pick_row(e, "robot_01") for e in events]
        async with sessions() as s:
            new = await insert_picks(s, rows)
            await s.commit()
        assert len(new) == 25
        async with sessions() as s:
            again = await insert_picks(s, rows[:10] + rows[:3])  # duplicates, also within one batch
            await s.commit()
        assert again == []
        async with sessions() as s:
            repo = PickRepository(s)
            assert await repo.count() == 25
            assert await repo.count(success=False) == len([e for e in events if not e.success])
            page = await repo.page(limit=10, offset=0)
            assert [p.pick_id for p in page] == [e.pick_id for e in reversed(events)][:10]
            page3 = await repo.page(limit=10, offset=20)
            assert [p.pick_id for p in page3] == [e.pick_id for e in reversed(events)][20:]
            row = await repo.get(page[0].id)
            assert row is not None and row.pick_pose == {
                "x": 0.45,
                "y": 0.24,
                "z": 0.02,
                "qx": 0,
                "qy": 0,
                "qz": 0,
                "qw": 1.0,
            }
            assert row.stage_durations == {"DETECT": 0.4, "PLAN": 0.6, "APPROACH": 2.0}
            failed = next(p for p in page if not p.success)
            assert failed.error_code == "GraspFailureError" and "slipped" in (failed.error_message or "")
            summary = await repo.summary(t0 + timedelta(hours=1))
        ok = [e for e in events if e.success]
        assert summary.total == 25 and summary.succeeded == len(ok)
        assert summary.success_rate == pytest.approx(len(ok) / 25)
        assert summary.avg_cycle_time_s == pytest.approx(sum(e.cycle_time_s for e in ok) / len(ok), rel=1e-5)
        assert summary.picks_today == 25
    finally:
        await engine.dispose()


def test_database_url_env_wins_and_is_validated(tmp_path):
    db = DatabaseSettings(url="sqlite+aiosqlite:///var/x.db")
    url = database_url(db, {"DATABASE_URL": f"sqlite+aiosqlite:///{tmp_path}/y.db"})
    assert url.endswith("/y.db")
    with pytest.raises(ConfigurationError, match=r"DATABASE_URL: .*postgresql\+asyncpg"):
        database_url(db, {"DATABASE_URL": "mysql://root@127.0.0.1/x"})
    rel = database_url(db, {})
    assert rel.startswith("sqlite+aiosqlite:////") and rel.endswith("var/x.db")  # made absolute


def test_start_of_day_is_utc_midnight():
    t = datetime(2026, 3, 4, 23, 59, tzinfo=UTC)
    assert start_of_day_utc(t) == datetime(2026, 3, 4, tzinfo=UTC)
