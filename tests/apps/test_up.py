"""``pickplace up`` lives until Ctrl-C: stop and e-stop leave every service up, Reset and Start resume."""

from __future__ import annotations

import asyncio
import io
from pathlib import Path

import httpx
import pytest
from rich.console import Console

from services.apps.cell import Cell
from services.apps.up import cell_keeps_running, run_pick_cell
from tests.apps.conftest import cell_settings

pytestmark = [pytest.mark.integration, pytest.mark.slow]


@pytest.mark.parametrize(
    ("cycles", "running", "done", "keeps"),
    [
        (0, False, 0, True),  # stopped or e-stopped, no cycle count asked: stay up
        (0, False, 7, True),
        (0, True, 3, True),
        (5, True, 5, True),  # the fifth cycle is still being wound up
        (5, False, 2, True),  # stopped before its count: stay up for Reset / Start / Ctrl-C
        (5, False, 5, False),  # `--cycles 5` finished: print the summary and end
    ],
)
def test_the_cell_ends_by_itself_only_after_the_cycles_it_was_asked_for(
    cycles: int, running: bool, done: int, keeps: bool
) -> None:
    assert cell_keeps_running(cycles, running, done) is keeps


class Ticks:
    """Counts the display's refreshes, so the test waits on the loop itself, not on the wall clock."""

    def __init__(self) -> None:
        self.count = 0
        self._changed = asyncio.Event()

    def __call__(self) -> None:
        self.count += 1
        self._changed.set()

    async def wait(self, run: asyncio.Task[object], n: int = 1) -> None:
        """``n`` more refreshes; fails at once if ``pickplace up`` ended instead."""
        target = self.count + n
        while self.count < target:
            self._changed.clear()
            changed = asyncio.ensure_future(self._changed.wait())
            await asyncio.wait({changed, run}, return_when=asyncio.FIRST_COMPLETED)
            changed.cancel()
            assert not run.done(), "pickplace up ended"


async def test_stop_and_estop_leave_the_embedded_cell_up_and_start_resumes(tmp_path: Path) -> None:
    s = cell_settings(
        tmp_path,
        gateway={"port": 0, "edge_grpc_port": 0},
        database={"url": f"sqlite+aiosqlite:///{tmp_path / 'cell.db'}"},
    )
    out = io.StringIO()
    ready: asyncio.Future[tuple[Cell, str]] = asyncio.get_running_loop().create_future()
    ticks = Ticks()
    run: asyncio.Task[object] = asyncio.create_task(
        run_pick_cell(s, 0, Console(file=out, width=120), lambda c, u: ready.set_result((c, u)), ticks)
    )
    try:
        async with asyncio.timeout(120):
            cell, url = await ready
            base, token = url.split("/#token=")
            runner = cell.task.runner  # type: ignore[union-attr]
            headers = {"Authorization": f"Bearer {token}"}
            async with httpx.AsyncClient(base_url=base, headers=headers, timeout=30) as api:
                r = await api.post("/api/v1/system/stop")
                assert r.status_code == 200 and r.json()["success"], r.text
                while runner.running:
                    await ticks.wait(run)
                await ticks.wait(
                    run, 2
                )  # the loop has seen the stopped task twice: it would have ended by now
                assert not run.done()

                r = await api.post("/api/v1/system/estop")
                assert r.status_code == 200 and r.json()["success"], r.text
                await ticks.wait(run, 2)
                assert not run.done()
                status = await api.get("/api/v1/system/status")
                assert status.status_code == 200, status.text

                # the dashboard's Reset (release + clear + enable), then Start: picking resumes
                r = await api.post("/api/v1/system/estop/release")
                assert r.status_code == 200 and r.json()["success"], r.text
                r = await api.post("/api/v1/system/start", json={})
                assert r.status_code == 200 and r.json()["success"], r.text
                while not runner.running:
                    await ticks.wait(run)
                await ticks.wait(run, 2)
                assert not run.done() and runner.running
    finally:
        run.cancel()  # what Ctrl-C does
        with pytest.raises(asyncio.CancelledError):
            await run
    assert "summary" in out.getvalue()
