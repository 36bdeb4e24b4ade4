"""Whether the cell runs a pick cycle, from the task's status: what shares the cell's CPU with it and can
wait gives way (vision's live detection loop, the twin's periodic camera renders), which took the CPU the
cycle's own detection and planning wait for. :class:`CycleWatch` decides (pure, given the time);
:func:`follow_cycles` feeds it the task's status from the bus."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pickplace.v1 import task_pb2

from services.common.keys import CellKeys

if TYPE_CHECKING:
    from services.common.bus import Bus

log = logging.getLogger("pickplace.cycle_watch")

STALE_S = 3.0  # the task says where it is at least twice a second (task.status_rate_hz): older is silence


@dataclass
class CycleWatch:
    """``on_status`` with each task status; ``active`` while the last one said a cycle is under way
    and is at most ``stale_s`` old (a task that fell silent mid-cycle does not stop the loop for good)."""

    stale_s: float = STALE_S
    _active_at: float | None = None  # when the last status saying "active" came (monotonic s)

    def on_status(self, cycle_active: bool, now: float) -> None:
        self._active_at = now if cycle_active else None

    def active(self, now: float) -> bool:
        return self._active_at is not None and now - self._active_at <= self.stale_s

    def gives_way(self, now: float, live_during_cycle: bool) -> bool:
        """Whether periodic work pauses now (``vision.live_during_cycle`` keeps it going)."""
        return not live_during_cycle and self.active(now)


def follow_cycles(
    bus: Bus, cell_id: str, watch: CycleWatch, stack: contextlib.ExitStack | contextlib.AsyncExitStack
) -> None:
    """Keep ``watch`` up to date from the task's status on ``bus`` (call on the event loop that reads
    ``watch``); the subscription ends with ``stack``."""
    loop = asyncio.get_running_loop()

    def on_status(_key: str, payload: bytes) -> None:  # a Zenoh thread: over to the loop
        try:
            active = task_pb2.TaskStatus.FromString(payload).cycle_active
        except Exception as exc:  # a bad status must not stop the service
            log.debug("ignoring an undecodable task status: %s", exc)
            return
        loop.call_soon_threadsafe(watch.on_status, active, time.monotonic())

    sub = bus.subscribe_callback(CellKeys(cell_id).task_status, on_status)

    def undeclare() -> None:
        with contextlib.suppress(Exception):  # the session may be closing already
            sub.undeclare()

    stack.callback(undeclare)
