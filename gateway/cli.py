"""``pickplace db upgrade|downgrade|current`` (mounted on the main CLI as the ``db`` group)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Annotated, TypeVar

import typer
from rich.console import Console

from services.common.errors import ConfigurationError
from services.common.settings import Settings, load_settings

db_app = typer.Typer(
    help="the gateway's database: pick history, system health, calibrations (Alembic migrations)",
    no_args_is_help=True,
)
console = Console(soft_wrap=True)  # one line per message: database URLs and paths stay copyable

ProfileOpt = Annotated[str | None, typer.Option("--profile", "-p", help="config profile (sim, nova5-real)")]
ConfigOpt = Annotated[str | None, typer.Option("--config", "-c", help="extra YAML config file")]
T = TypeVar("T")


def _settings(profile: str | None, config: str | None) -> Settings:
    try:
        return load_settings(profile, config)
    except ConfigurationError as exc:
        console.print(f"[red]configuration error:[/red] {exc}")
        raise typer.Exit(2) from None


def _with_engine(s: Settings, work: Callable[..., Awaitable[T]]) -> tuple[str, T]:
    from gateway.db.engine import database_url, make_engine, redact

    try:
        url = database_url(s.database)
    except ConfigurationError as exc:
        console.print(f"[red]configuration error:[/red] {exc}")
        raise typer.Exit(2) from None

    async def run() -> T:
        engine = make_engine(s.database, url)
        try:
            return await work(engine)
        finally:
            await engine.dispose()

    try:
        return redact(url), asyncio.run(run())
    except (OSError, ConfigurationError) as exc:
        console.print(f"[red]database {redact(url)}:[/red] {type(exc).__name__}: {exc}")
        raise typer.Exit(1) from None
    except Exception as exc:  # SQLAlchemy/driver errors: say which database and why, no traceback
        first = str(exc).splitlines()[0] if str(exc) else ""
        console.print(f"[red]database {redact(url)}:[/red] {type(exc).__name__}: {first}")
        raise typer.Exit(1) from None


@db_app.command("upgrade")
def upgrade(
    revision: Annotated[str, typer.Argument(help="target revision")] = "head",
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Create or update the tables (``DATABASE_URL`` or ``database.url``)."""
    from gateway.db import migrate

    s = _settings(profile, config)
    where, rev = _with_engine(s, lambda e: migrate.upgrade(e, s.database, revision))
    console.print(f"database {where} is at revision [green]{rev}[/green] (head {migrate.head_revision()})")


@db_app.command("downgrade")
def downgrade(
    revision: Annotated[str, typer.Argument(help="target revision ('-1' = one step, 'base' = empty)")] = "-1",
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Step the schema back (``base`` drops every pickplace table)."""
    from gateway.db import migrate

    s = _settings(profile, config)
    where, rev = _with_engine(s, lambda e: migrate.downgrade(e, revision))
    console.print(f"database {where} is at revision [yellow]{rev or 'base (no tables)'}[/yellow]")


@db_app.command("current")
def current(profile: ProfileOpt = None, config: ConfigOpt = None) -> None:
    """Show the database's revision and whether the gateway can start on it."""
    from gateway.db import migrate

    s = _settings(profile, config)
    where, rev = _with_engine(s, migrate.current_revision)
    head = migrate.head_revision()
    if rev == head:
        console.print(f"database {where}: revision [green]{rev}[/green] (up to date)")
    else:
        console.print(
            f"database {where}: revision [yellow]{rev or 'none'}[/yellow], newest is {head}: "
            "run `pickplace db upgrade`"
        )
        raise typer.Exit(1)
