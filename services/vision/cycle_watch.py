"""Whether the cell runs a pick cycle, from the task's status (pure): the live detection loop gives way
to it. The loop's detection (and, in the twin, its render) took the CPU the cycle's own detection and
planning wait for."""

from __future__ import annotations

from dataclasses import dataclass

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
