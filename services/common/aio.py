"""Running a command's top-level coroutine (Ctrl-C and SIGTERM cancel it cleanly); stopping background tasks."""

from __future__ import annotations

import asyncio
import contextlib
import signal
from collections.abc import Awaitable
from typing import Any


def run_until_signal(main: Awaitable[Any]) -> Any:
    """``asyncio.run`` ``main`` with SIGINT/SIGTERM cancelling it (its cleanup runs); raises
    ``asyncio.CancelledError`` when a signal stopped it."""

    async def runner() -> Any:
        task = asyncio.current_task()
        assert task is not None
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError):  # not on every platform's loop
                loop.add_signal_handler(sig, task.cancel)
        return await main

    return asyncio.run(runner())


async def cancel_and_wait(task: asyncio.Task[Any] | None) -> None:
    """Cancel a background task and wait until it has finished its cleanup (None: nothing to do)."""
    if task is None:
        return
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task


async def first_of(*events: asyncio.Event | None) -> None:
    """Until any of ``events`` (None: left out) is set."""
    waits = [asyncio.ensure_future(e.wait()) for e in events if e is not None]
    try:
        await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for w in waits:
            w.cancel()
