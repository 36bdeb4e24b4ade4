"""Engine construction, URL resolution and the "is this database migrated?" check."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import ValidationError
from sqlalchemy import event
from sqlalchemy.engine import make_url
from sqlalchemy.ext.asyncio import AsyncEngine, async_sessionmaker, create_async_engine
from sqlalchemy.ext.asyncio import AsyncSession as AsyncSession

from services.common.errors import ConfigurationError
from services.common.settings import REPO_ROOT, DatabaseSettings

DATABASE_URL_ENV = "DATABASE_URL"


def database_url(db: DatabaseSettings, environ: Mapping[str, str] = os.environ) -> str:
    """The URL to use: ``DATABASE_URL`` (the docker-compose convention) wins over ``database.url``.

    A relative SQLite path is taken from the repository root, and its folder is created.
    """
    url = environ.get(DATABASE_URL_ENV) or db.url
    if url != db.url:
        # same validation as the settings field, so a bad DATABASE_URL is refused as clearly
        try:
            DatabaseSettings.model_validate({**db.model_dump(), "url": url})
        except ValidationError as exc:
            raise ConfigurationError(f"{DATABASE_URL_ENV}: {exc.errors()[0]['msg']}") from exc
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite" and parsed.database and parsed.database != ":memory:":
        path = Path(parsed.database)
        if not path.is_absolute():
            path = REPO_ROOT / path
        path.parent.mkdir(parents=True, exist_ok=True)
        url = parsed.set(database=str(path)).render_as_string(hide_password=False)
    return url


def redact(url: str) -> str:
    return make_url(url).render_as_string(hide_password=True)


def make_engine(db: DatabaseSettings, url: str) -> AsyncEngine:
    parsed = make_url(url)
    kwargs: dict[str, Any] = {"pool_pre_ping": True}
    if parsed.get_backend_name() == "postgresql":
        server_settings = {"application_name": "pickplace-gateway"}
        if db.schema_name:
            server_settings["search_path"] = db.schema_name
        kwargs |= {
            "pool_size": db.pool_size,
            "max_overflow": db.pool_size,
            "pool_timeout": db.connect_timeout_s,
            "connect_args": {
                "timeout": db.connect_timeout_s,
                "command_timeout": db.command_timeout_s,
                "server_settings": server_settings,
            },
        }
    else:
        kwargs["connect_args"] = {"timeout": db.command_timeout_s}
    engine = create_async_engine(url, **kwargs)
    if parsed.get_backend_name() == "sqlite":
        event.listen(engine.sync_engine, "connect", _sqlite_pragmas)
    return engine


def _sqlite_pragmas(dbapi_conn: Any, _record: Any) -> None:
    # WAL lets the dashboard read while the pick writer writes; a busy timeout instead of "locked".
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA busy_timeout=5000")
    cur.execute("PRAGMA foreign_keys=ON")
    cur.close()


def session_factory(engine: AsyncEngine) -> async_sessionmaker[AsyncSession]:
    return async_sessionmaker(engine, expire_on_commit=False)
