"""A small time-bounded cache for the expensive aggregate reads (counts and summaries over the history).

The pick writer clears it whenever it stores picks, so this gateway's own writes show at once;
another writer's show within ``ttl_s``. A value read while a clear came is answered but not kept: it may
predate the write (the operator panel showed a stored pick in the history while GET /api/v1/metrics
still answered "no picks" from a summary read just before the write).
"""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable, Hashable
from typing import Any, TypeVar

T = TypeVar("T")


class ReadCache:
    def __init__(self, ttl_s: float = 2.0, clock: Callable[[], float] = time.monotonic):
        self.ttl_s = ttl_s
        self._clock = clock
        self._values: dict[Hashable, tuple[float, Any]] = {}
        self._generation = 0  # clears so far
        self.hits = 0
        self.misses = 0

    async def get(self, key: Hashable, compute: Callable[[], Awaitable[T]]) -> T:
        now = self._clock()
        hit = self._values.get(key)
        if hit is not None and now - hit[0] < self.ttl_s:
            self.hits += 1
            return hit[1]
        self.misses += 1
        generation = self._generation
        value = await compute()
        if generation == self._generation:
            self._values[key] = (now, value)
        return value

    def clear(self) -> None:
        self._values.clear()
        self._generation += 1
