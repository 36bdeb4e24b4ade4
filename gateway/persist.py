"""Pick events from the bus into the database, exactly once, none lost while the database is down.

:class:`PickBuffer` is a FIFO: events wait in memory up to a bound, then are appended to a
JSONL spill file (and once the file has anything in it, newer events queue behind it there, so
order holds). :class:`PickWriter` takes batches from the front, inserts them with
"ON CONFLICT (pick_id) DO NOTHING", and only then removes them from the buffer: an outage
(or a crash) between insert and removal means the batch is sent again, and the unique
``pick_id`` keeps it stored once. While the database is unreachable it retries with capped
exponential backoff, on its own clock and sleep (injectable: a test can hold the database away
for minutes of the writer's time in a second), and counts how long each outage lasted on it. At
shutdown whatever is still in memory is spilled to the file, which the next start reads first.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import logging
import os
import time
from collections import deque
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from pickplace.v1 import task_pb2
from sqlalchemy import exc as sa_exc

from services.common.errors import InvalidInputError

log = logging.getLogger("pickplace.gateway.persist")


class PickBuffer:
    """Memory up to ``capacity`` events, then the spill file; FIFO across both."""

    def __init__(self, capacity: int, spill_path: Path | None):
        if capacity < 1:
            raise InvalidInputError(f"pick buffer capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self.spill_path = spill_path
        self._memory: deque[task_pb2.PickEvent] = deque()
        self._spilled = 0
        if spill_path is not None:
            spill_path.parent.mkdir(parents=True, exist_ok=True)
            if spill_path.exists():
                self._spilled = sum(1 for line in spill_path.read_text().splitlines() if line.strip())

    def __len__(self) -> int:
        return len(self._memory) + self._spilled

    @property
    def spilled(self) -> int:
        return self._spilled

    def put(self, ev: task_pb2.PickEvent) -> None:
        if self._spilled == 0 and len(self._memory) < self.capacity:
            self._memory.append(ev)
            return
        if self.spill_path is None:
            # no file configured: the bound is hard, the oldest would have to go; refuse instead
            raise OverflowError(f"pick buffer full ({self.capacity} events) and no spill file configured")
        self._append([ev])

    def peek(self, n: int) -> list[task_pb2.PickEvent]:
        """Up to ``n`` events from the front (refilling memory from the spill file when it is empty)."""
        if not self._memory and self._spilled:
            self._refill()
        return [self._memory[i] for i in range(min(n, len(self._memory)))]

    def drop(self, n: int) -> None:
        """Remove the first ``n`` events (after they were written)."""
        for _ in range(min(n, len(self._memory))):
            self._memory.popleft()

    def spill_all(self) -> int:
        """Move every in-memory event to the front of the spill file (at shutdown). Returns how many."""
        if not self._memory or self.spill_path is None:
            return 0
        moved = list(self._memory)
        rest = self.spill_path.read_text() if self.spill_path.exists() else ""
        tmp = self.spill_path.with_suffix(".tmp")
        tmp.write_text("".join(_encode(ev) for ev in moved) + rest)
        os.replace(tmp, self.spill_path)
        self._spilled += len(moved)
        self._memory.clear()
        return len(moved)

    def _append(self, events: Sequence[task_pb2.PickEvent]) -> None:
        assert self.spill_path is not None
        with self.spill_path.open("a") as f:
            f.write("".join(_encode(ev) for ev in events))
            f.flush()
        self._spilled += len(events)

    def _refill(self) -> None:
        assert self.spill_path is not None
        lines = [line for line in self.spill_path.read_text().splitlines() if line.strip()]
        take, keep = lines[: self.capacity], lines[self.capacity :]
        for line in take:
            try:
                self._memory.append(_decode(line))
            except (ValueError, KeyError) as exc:  # a torn last line after a crash
                log.error("dropping unreadable line in %s: %s", self.spill_path, exc)
        tmp = self.spill_path.with_suffix(".tmp")
        tmp.write_text("".join(line + "\n" for line in keep))
        os.replace(tmp, self.spill_path)
        self._spilled = len(keep)


def _encode(ev: task_pb2.PickEvent) -> str:
    return json.dumps({"pick_id": ev.pick_id, "pb": base64.b64encode(ev.SerializeToString()).decode()}) + "\n"


def _decode(line: str) -> task_pb2.PickEvent:
    return task_pb2.PickEvent.FromString(base64.b64decode(json.loads(line)["pb"]))


@dataclass(frozen=True)
class WrittenPick:
    id: int
    event: task_pb2.PickEvent


# (events) -> [(db id, pick_id)] of the rows that were new
InsertFn = Callable[[Sequence[task_pb2.PickEvent]], Awaitable[list[tuple[int, str]]]]


def is_data_error(exc: BaseException) -> bool:
    """Errors that retrying cannot fix (bad rows), as opposed to the database being unreachable."""
    return isinstance(exc, InvalidInputError | sa_exc.DataError | sa_exc.IntegrityError)


class PickWriter:
    """Drains a :class:`PickBuffer` into the database. ``offer`` from the event loop; ``run`` as a task."""

    def __init__(
        self,
        buffer: PickBuffer,
        insert: InsertFn,
        *,
        batch_size: int = 100,
        retry_initial_s: float = 0.2,
        retry_max_s: float = 5.0,
        on_written: Callable[[list[WrittenPick]], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
    ):
        self.buffer = buffer
        self._insert = insert
        self.batch_size = batch_size
        self.retry_initial_s = retry_initial_s
        self.retry_max_s = retry_max_s
        self._on_written = on_written
        self._clock, self._sleep = clock, sleep
        self._wake = asyncio.Event()
        self._empty = asyncio.Event()
        self._update_empty()
        self.database_ok = True
        self.last_error: str | None = None
        self.written = 0
        self.rejected = 0
        self.outage_since: float | None = None  # on the writer's clock, while the database is away
        self.longest_outage_s = 0.0

    def offer(self, ev: task_pb2.PickEvent) -> None:
        self.buffer.put(ev)
        self._empty.clear()
        self._wake.set()

    def _update_empty(self) -> None:
        if len(self.buffer) == 0:
            self._empty.set()
        else:
            self._empty.clear()

    async def drained(self, timeout_s: float) -> None:
        """Wait until every buffered event is written (TimeoutError after ``timeout_s``)."""
        async with asyncio.timeout(timeout_s):
            await self._empty.wait()

    async def run(self) -> None:
        delay = self.retry_initial_s
        while True:
            batch = self.buffer.peek(self.batch_size)
            if not batch:
                self._update_empty()
                self._wake.clear()
                await self._wake.wait()
                continue
            try:
                new = await self._insert(batch)
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                failure = await self._isolate(batch) if is_data_error(exc) else exc
                if failure is None:
                    self._update_empty()
                    continue
                self._outage(failure, delay)
                await self._sleep(delay)  # new events do not shorten the backoff
                delay = min(delay * 2, self.retry_max_s)
                continue
            if not self.database_ok:
                self._back()
            self.database_ok, self.last_error, delay = True, None, self.retry_initial_s
            self.buffer.drop(len(batch))
            self.written += len(new)
            self._update_empty()
            if new and self._on_written is not None:
                by_id = {ev.pick_id: ev for ev in batch}
                self._on_written([WrittenPick(i, by_id[p]) for i, p in new])

    async def _isolate(self, batch: list[task_pb2.PickEvent]) -> BaseException | None:
        """One bad row must not hold up the others: write the batch one at a time.

        Returns the error if the database went away meanwhile (the rest stays buffered).
        """
        for ev in batch:
            try:
                new = await self._insert([ev])
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                if not is_data_error(exc):
                    return exc
                self.rejected += 1
                log.error("pick %s cannot be stored, dropped: %s", ev.pick_id, exc)
            else:
                self.written += len(new)
                if new and self._on_written is not None:
                    self._on_written([WrittenPick(new[0][0], ev)])
            self.buffer.drop(1)
        return None

    def outage_s(self) -> float:
        """How long the database has been away, on the writer's clock (0 while it is there)."""
        return 0.0 if self.outage_since is None else self._clock() - self.outage_since

    def _outage(self, exc: BaseException, delay: float) -> None:
        text = f"{type(exc).__name__}: {exc}".splitlines()[0][:300]
        if self.database_ok:
            log.error("database unavailable, buffering pick events (retry in %.1fs): %s", delay, text)
            self.outage_since = self._clock()
        self.database_ok, self.last_error = False, text

    def _back(self) -> None:
        lasted = self.outage_s()
        self.longest_outage_s = max(self.longest_outage_s, lasted)
        self.outage_since = None
        log.warning("database back after %.1f s: writing %d buffered pick event(s)", lasted, len(self.buffer))

    async def flush(self, timeout_s: float) -> None:
        """Write everything buffered now, without retrying (at shutdown); raises on failure."""
        async with asyncio.timeout(timeout_s):
            while batch := self.buffer.peek(self.batch_size):
                new = await self._insert(batch)
                self.buffer.drop(len(batch))
                self.written += len(new)
        self._update_empty()

    def shutdown(self) -> int:
        """Spill what is still in memory so the next start writes it. Returns how many."""
        with contextlib.suppress(OverflowError):
            return self.buffer.spill_all()
        return 0
