"""Alembic, configured in code (no alembic.ini in the working directory needed).

The async engine hands a sync connection to Alembic through ``config.attributes``,
so migrations run the same way from the CLI, from the embedded app and from tests.
"""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, text
from sqlalchemy.ext.asyncio import AsyncEngine

from services.common.errors import ConfigurationError
from services.common.settings import DatabaseSettings

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"


def alembic_config() -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    return cfg


def head_revision() -> str:
    head = ScriptDirectory.from_config(alembic_config()).get_current_head()
    assert head is not None, "no migrations found"
    return head


def _with_connection(conn: Connection, fn_name: str, revision: str) -> None:
    cfg = alembic_config()
    cfg.attributes["connection"] = conn
    getattr(command, fn_name)(cfg, revision)


async def _ensure_schema(engine: AsyncEngine, db: DatabaseSettings) -> None:
    if db.schema_name and engine.dialect.name == "postgresql":
        async with engine.begin() as conn:
            await conn.execute(text(f'CREATE SCHEMA IF NOT EXISTS "{db.schema_name}"'))


async def upgrade(engine: AsyncEngine, db: DatabaseSettings, revision: str = "head") -> str | None:
    await _ensure_schema(engine, db)
    async with engine.begin() as conn:
        await conn.run_sync(_with_connection, "upgrade", revision)
    return await current_revision(engine)


async def downgrade(engine: AsyncEngine, revision: str = "-1") -> str | None:
    async with engine.begin() as conn:
        await conn.run_sync(_with_connection, "downgrade", revision)
    return await current_revision(engine)


async def current_revision(engine: AsyncEngine) -> str | None:
    async with engine.connect() as conn:
        return await conn.run_sync(lambda c: MigrationContext.configure(c).get_current_revision())


async def require_head(engine: AsyncEngine, url_for_humans: str) -> None:
    """Refuse to run against a database that is not at the newest migration."""
    current = await current_revision(engine)
    head = head_revision()
    if current != head:
        state = "has no pickplace tables (never migrated)" if current is None else f"is at revision {current}"
        raise ConfigurationError(
            f"database {url_for_humans} {state}, the gateway needs revision {head}: "
            "run `pickplace db upgrade` first"
        )
