"""The gateway's SQL database."""

from __future__ import annotations

from pydantic import Field, field_validator

from services.common.settings.base import Model


class DatabaseSettings(Model):
    """The gateway's SQL database: pick history, system health, calibrations (LLD §8.2).

    SQLite (aiosqlite) is the embedded default; PostgreSQL through asyncpg in deployments
    (``DATABASE_URL=postgresql+asyncpg://…`` or ``PICKPLACE_DATABASE__URL``).
    """

    url: str = "sqlite+aiosqlite:///var/pickplace.db"
    schema_name: str | None = Field(
        None, pattern=r"^[a-z_][a-z0-9_]{0,62}$", description="PostgreSQL schema (search_path); None = public"
    )
    auto_migrate: bool = Field(False, description="upgrade to the newest revision at start (embedded run)")
    pool_size: int = Field(5, ge=1, le=100)
    connect_timeout_s: float = Field(5.0, gt=0, le=60)
    command_timeout_s: float = Field(10.0, gt=0, le=300)

    @field_validator("url")
    @classmethod
    def _driver(cls, v: str) -> str:
        if not v.startswith(("sqlite+aiosqlite://", "postgresql+asyncpg://")):
            scheme = v.split("://", 1)[0] if "://" in v else v[:20]
            raise ValueError(
                f"database url must use sqlite+aiosqlite:// or postgresql+asyncpg://, got {scheme!r}"
            )
        return v
