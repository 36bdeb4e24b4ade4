"""`pickplace db upgrade|downgrade|current` through the real command line app."""

from __future__ import annotations

from typer.testing import CliRunner

from gateway.db.migrate import head_revision
from services.apps.cli import app


def test_db_commands_on_sqlite(tmp_path, monkeypatch):
    monkeypatch.setenv("DATABASE_URL", f"sqlite+aiosqlite:///{tmp_path / 'cli.db'}")
    monkeypatch.setenv("PICKPLACE_LOGGING__FILE", str(tmp_path / "log.txt"))
    runner = CliRunner()
    r = runner.invoke(app, ["db", "current"])
    assert r.exit_code == 1 and "pickplace db upgrade" in r.output
    r = runner.invoke(app, ["db", "upgrade"])
    # upgraded to the newest migration there is (0002_pick_outcome today)
    assert r.exit_code == 0 and f"revision {head_revision()} (head" in r.output.replace("\n", "")
    r = runner.invoke(app, ["db", "current"])
    assert r.exit_code == 0 and "up to date" in r.output
    r = runner.invoke(app, ["db", "downgrade", "base"])
    assert r.exit_code == 0 and "no tables" in r.output
    r = runner.invoke(app, ["db", "current"])
    assert r.exit_code == 1


def test_db_command_names_a_bad_url(monkeypatch):
    monkeypatch.setenv("DATABASE_URL", "mysql://root@127.0.0.1/test")
    r = CliRunner().invoke(app, ["db", "current"])
    assert r.exit_code == 2 and "postgresql+asyncpg" in r.output


def test_db_command_reports_an_unreachable_server(monkeypatch):
    from tests.conftest import free_port

    monkeypatch.setenv("DATABASE_URL", f"postgresql+asyncpg://postgres@127.0.0.1:{free_port()}/test")
    monkeypatch.setenv("PICKPLACE_DATABASE__CONNECT_TIMEOUT_S", "1")
    r = CliRunner().invoke(app, ["db", "upgrade"])
    assert r.exit_code == 1 and "127.0.0.1" in r.output and "Traceback" not in r.output
