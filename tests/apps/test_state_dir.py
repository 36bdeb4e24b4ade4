"""Each cell keeps its files in its own state directory; each run writes a session log of its own."""

from __future__ import annotations

import logging
from datetime import UTC, datetime
from pathlib import Path

from services.apps.launcher import session_log, session_log_path, with_state_dir
from services.common.settings import REPO_ROOT, load_settings


def test_the_state_directory_is_the_cells_own(tmp_path: Path) -> None:
    a, b = load_settings("sim"), load_settings("sim", overrides={"cell_id": "bay2"})
    pa, pb = a.state.path(a.cell_id, REPO_ROOT), b.state.path(b.cell_id, REPO_ROOT)
    assert pa == REPO_ROOT / "var" / "cell1" and pb == REPO_ROOT / "var" / "bay2"
    assert not pa.is_relative_to(pb) and not pb.is_relative_to(pa)  # wiping one leaves the other
    c = load_settings("sim", overrides={"state": {"dir": str(tmp_path / "s")}})
    assert c.state.path(c.cell_id, REPO_ROOT) == tmp_path / "s"
    d = load_settings("sim", overrides={"state": {"dir": "run/x"}})
    assert d.state.path(d.cell_id, REPO_ROOT) == REPO_ROOT / "run" / "x"


def test_a_cells_database_and_spill_file_are_in_its_state_directory(tmp_path: Path) -> None:
    s = with_state_dir(load_settings("sim", overrides={"cell_id": "bay2"}))
    assert s.gateway.pick_spill_file == str(REPO_ROOT / "var" / "bay2" / "gateway" / "pick_spill.jsonl")
    assert s.database.url == f"sqlite+aiosqlite:///{REPO_ROOT / 'var' / 'bay2' / 'pickplace.db'}"
    mine, db = str(tmp_path / "spill.jsonl"), f"sqlite+aiosqlite:///{tmp_path / 'mine.db'}"
    s = with_state_dir(
        load_settings("sim", overrides={"gateway": {"pick_spill_file": mine}, "database": {"url": db}})
    )
    assert s.gateway.pick_spill_file == mine and s.database.url == db  # configured paths are kept


def test_a_session_log_per_run_named_by_its_start_beside_the_main_log(tmp_path: Path) -> None:
    s = load_settings("sim", overrides={"logging": {"file": str(tmp_path / "log" / "pickplace.log")}})
    started = datetime(2026, 12, 1, 21, 5, 9, tzinfo=UTC)
    assert session_log_path(s, started, "up") == tmp_path / "log" / "session-cell1-up-20261201T210509Z.log"
    root = logging.getLogger()
    level = root.level
    root.setLevel(logging.INFO)  # as setup_logging leaves it for a run
    try:
        with session_log(s, "up") as path:
            assert path is not None and path.parent == tmp_path / "log"
            logging.getLogger("pickplace.test").warning("inside the session")
    finally:
        root.setLevel(level)
    logging.getLogger("pickplace.test").warning("after the session")
    text = path.read_text()
    assert "inside the session" in text and "after the session" not in text
    assert "session of cell cell1 (up) started" in text
    off = load_settings("sim", overrides={"state": {"session_log": False}})
    with session_log(off, "up") as none:
        assert none is None
