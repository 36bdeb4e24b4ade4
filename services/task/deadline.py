"""Deadlines on a given clock: what the arm does is timed on the controller's clock (pure asyncio).

``within(aw, seconds, what, clock)`` awaits ``aw`` and fails it with a RobotError once ``clock`` (the
controller's: the feedback TimeStamp in the cell, the fake controller's time in tests) has advanced
by ``seconds`` — so a motion deadline means the same at 1× on a real cell, at N× in the twin and on a
busy machine whose simulator slowed its clock. The clock is read again every ``poll_s`` of wall time
(a deadline check, not a wait for the arm); a clock that stops (a lost link freezes the feedback) is
caught by a wall-clock backstop ``backstop`` times the deadline.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import TypeVar

from services.common.errors import RobotError

T = TypeVar("T")

POLL_S = 0.05  # wall seconds between reads of the controller clock while a deadline runs
WALL_BACKSTOP = 10.0  # a frozen controller clock still ends the wait after this many deadlines of wall time


async def within(
    aw: Awaitable[T],
    seconds: float,
    what: str,
    clock: Callable[[], float],
    wall_clock: Callable[[], float] = time.monotonic,
    poll_s: float = POLL_S,
    backstop: float = WALL_BACKSTOP,
) -> T:
    """``await aw``, or RobotError naming ``what`` when ``seconds`` pass on ``clock`` first (``aw`` is
    cancelled)."""
    task = asyncio.ensure_future(aw)
    t_end = clock() + seconds
    wall_end = wall_clock() + backstop * seconds
    try:
        while True:
            done, _ = await asyncio.wait({task}, timeout=poll_s)
            if done:
                return task.result()
            if clock() >= t_end:
                raise RobotError(
                    f"{what} did not finish within its {seconds:.0f} s deadline (controller clock)"
                )
            if wall_clock() >= wall_end:
                raise RobotError(
                    f"{what} did not finish within {backstop * seconds:.0f} s of wall time "
                    "(the controller clock stood still)"
                )
    finally:
        if not task.done():
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
