"""No pick lost, none stored twice: the buffer, the writer, and a real PostgreSQL outage mid-run."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Sequence

import pytest
from pickplace.v1 import task_pb2
from sqlalchemy import func, select, text

from gateway.db.engine import make_engine, session_factory
from gateway.db.models import Pick
from gateway.persist import PickBuffer, PickWriter
from services.common.bus import Bus
from services.common.errors import InvalidInputError
from services.common.keys import CellKeys
from services.common.settings import DatabaseSettings
from tests.conftest import free_port
from tests.gateway.conftest import (
    PG_URL,
    gateway_settings,
    migrate_up,
    pick_event,
    postgres_schema,
    running_gateway,
    wait_until,
)


# ---------------------------------------------------------------------------- buffer
def test_buffer_spills_in_order_and_survives_a_restart(tmp_path):
    spill = tmp_path / "spill.jsonl"
    buf = PickBuffer(capacity=3, spill_path=spill)
    events = [pick_event(i) for i in range(8)]
    for ev in events:
        buf.put(ev)
    assert len(buf) == 8 and buf.spilled == 5
    assert [e.pick_id for e in buf.peek(10)] == [e.pick_id for e in events[:3]]
    buf.drop(2)
    # one left in memory: it stays ahead of the spilled ones
    assert [e.pick_id for e in buf.peek(10)] == [events[2].pick_id]
    buf.drop(1)
    assert [e.pick_id for e in buf.peek(10)] == [e.pick_id for e in events[3:6]]  # refilled from the file
    assert buf.spilled == 2
    # shutdown: memory goes back to the front of the file; a new buffer finds all of it
    assert buf.spill_all() == 3
    again = PickBuffer(capacity=3, spill_path=spill)
    assert len(again) == 5
    seen = []
    while batch := again.peek(2):
        seen += [e.pick_id for e in batch]
        again.drop(len(batch))
    assert seen == [e.pick_id for e in events[3:]]
    assert spill.read_text() == ""


def test_buffer_round_trips_every_field(tmp_path):
    buf = PickBuffer(capacity=1, spill_path=tmp_path / "s.jsonl")
    a, b = pick_event(1, success=False), pick_event(2)
    buf.put(a)
    buf.put(b)  # spilled
    buf.drop(1)
    assert buf.peek(1)[0] == b


def test_buffer_without_a_file_refuses_instead_of_dropping():
    buf = PickBuffer(capacity=2, spill_path=None)
    buf.put(pick_event(0))
    buf.put(pick_event(1))
    with pytest.raises(OverflowError, match="no spill file"):
        buf.put(pick_event(2))
    with pytest.raises(InvalidInputError):
        PickBuffer(capacity=0, spill_path=None)


# ---------------------------------------------------------------------------- writer (fake store)
class FlakyStore:
    """An in-memory table with a unique pick_id; ``down`` makes inserts fail like a lost connection."""

    def __init__(self) -> None:
        self.rows: dict[str, int] = {}
        self.down = False
        self.calls = 0

    async def insert(self, events: Sequence[task_pb2.PickEvent]) -> list[tuple[int, str]]:
        self.calls += 1
        if self.down:
            raise ConnectionRefusedError("database down")
        new = []
        for ev in events:
            if ev.pick_id == "bad":
                raise InvalidInputError("bad row")
            if ev.pick_id not in self.rows:
                self.rows[ev.pick_id] = len(self.rows) + 1
                new.append((self.rows[ev.pick_id], ev.pick_id))
        return new


async def test_writer_buffers_through_an_outage_and_writes_once(tmp_path):
    store = FlakyStore()
    written: list[str] = []
    writer = PickWriter(
        PickBuffer(4, tmp_path / "s.jsonl"),
        store.insert,
        batch_size=3,
        retry_initial_s=0.01,
        retry_max_s=0.05,
        on_written=lambda ps: written.extend(p.event.pick_id for p in ps),
    )
    task = asyncio.create_task(writer.run())
    try:
        first = [pick_event(i) for i in range(3)]
        for ev in first:
            writer.offer(ev)
        await writer.drained(5.0)
        store.down = True
        during = [pick_event(i) for i in range(3, 15)]  # more than the memory bound: spills to the file
        for ev in during:
            writer.offer(ev)
        await wait_until(lambda: not writer.database_ok, 5.0, "the writer to notice the outage")
        assert writer.buffer.spilled > 0
        writer.offer(first[0])  # a duplicate delivery
        store.down = False
        await writer.drained(5.0)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    assert sorted(store.rows) == sorted(e.pick_id for e in first + during)
    assert sorted(written) == sorted(store.rows)  # each reported once
    assert writer.database_ok and writer.last_error is None


async def test_writer_drops_only_the_bad_row():
    store = FlakyStore()
    writer = PickWriter(PickBuffer(10, None), store.insert, batch_size=10)
    task = asyncio.create_task(writer.run())
    try:
        good = [pick_event(i) for i in range(3)]
        writer.offer(good[0])
        writer.offer(pick_event(9, pick_id="bad"))
        writer.offer(good[1])
        writer.offer(good[2])
        await writer.drained(5.0)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    assert sorted(store.rows) == sorted(e.pick_id for e in good)
    assert writer.rejected == 1


# ---------------------------------------------------------------------------- PostgreSQL outage
class TcpProxy:
    """A loopback TCP proxy that can be cut (all connections closed, nothing accepted) and restored."""

    def __init__(self, target_port: int):
        self.target_port = target_port
        self.port = free_port()
        self._server: asyncio.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self.connections = 0

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._handle, "127.0.0.1", self.port, reuse_address=True)

    async def cut(self) -> None:
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None
        for w in list(self._writers):
            w.close()
        self._writers.clear()

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections += 1
        try:
            up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.target_port)
        except OSError:
            writer.close()
            return
        self._writers |= {writer, up_writer}

        async def pipe(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
            with contextlib.suppress(Exception):
                while data := await src.read(65536):
                    dst.write(data)
                    await dst.drain()
            dst.close()

        await asyncio.gather(pipe(reader, up_writer), pipe(up_reader, writer))
        self._writers -= {writer, up_writer}


@contextlib.asynccontextmanager
async def postgres_behind_proxy() -> AsyncIterator[tuple[DatabaseSettings, DatabaseSettings, TcpProxy]]:
    """A migrated PostgreSQL schema, reached directly and through a proxy the test can cut."""
    async with postgres_schema() as schema:
        direct = DatabaseSettings(url=PG_URL, schema_name=schema)
        await migrate_up(direct)
        proxy = TcpProxy(5432)
        await proxy.start()
        via_proxy = direct.model_copy(
            update={
                "url": PG_URL.replace("127.0.0.1:5432", f"127.0.0.1:{proxy.port}"),
                "connect_timeout_s": 1.0,
                "command_timeout_s": 2.0,
            }
        )
        try:
            yield direct, via_proxy, proxy
        finally:
            await proxy.cut()


@pytest.mark.integration
@pytest.mark.postgres
async def test_no_pick_lost_when_postgres_connection_is_cut(settings, tmp_path):
    async with postgres_behind_proxy() as (direct, via_proxy, proxy):
        # small memory bound so the outage also exercises the spill file
        s = gateway_settings(settings, via_proxy, tmp_path, pick_buffer_size=5, pick_batch_size=4)
        keys = CellKeys(s.cell_id)
        published: list[str] = []
        async with Bus(s.zenoh) as bus, running_gateway(s, bus) as gw:
            cell = gw.cell

            async def publish(n: int) -> None:
                for i in range(n):
                    ev = pick_event(len(published) + i)
                    bus.publish(keys.pick_events, ev)
                    published.append(ev.pick_id)
                    await asyncio.sleep(0.005)

            await publish(10)
            await wait_until(lambda: cell.writer.written == 10, 10.0, "the first 10 picks in the database")
            await proxy.cut()
            await publish(20)
            await wait_until(lambda: not cell.writer.database_ok, 10.0, "the writer to see the outage")
            await wait_until(lambda: len(cell.writer.buffer) == 20, 10.0, "20 picks buffered")
            assert cell.writer.buffer.spilled > 0, "the memory bound (5) should have spilled to disk"
            r = await gw.client.get("/api/v1/system/status")
            assert r.status_code == 200 and r.json()["database"] == "unavailable"
            assert r.json()["pick_buffer"] == 20
            r = await gw.client.get("/api/v1/picks")
            assert r.status_code == 503 and r.json()["error"] == "DatabaseUnavailable"
            # the same pick delivered twice while down
            bus.publish(keys.pick_events, pick_event(0, pick_id=published[3]))
            await proxy.start()
            await publish(5)
            await wait_until(
                lambda: len(cell.writer.buffer) == 0 and cell.writer.database_ok,
                15.0,
                "the buffer to drain after the database came back",
            )
            await wait_until(lambda: cell.writer.written == 35, 10.0, "35 distinct picks written")

        engine = make_engine(direct, PG_URL)
        try:
            async with session_factory(engine)() as session:
                ids = list((await session.scalars(select(Pick.pick_id))).all())
                dup = await session.scalar(text("SELECT count(*) - count(DISTINCT pick_id) FROM picks"))
                total = await session.scalar(select(func.count()).select_from(Pick))
        finally:
            await engine.dispose()
    assert total == 35 and dup == 0
    assert sorted(ids) == sorted(published)


@pytest.mark.integration
@pytest.mark.postgres
async def test_picks_buffered_at_shutdown_are_written_by_the_next_start(settings, tmp_path):
    async with postgres_behind_proxy() as (_, via_proxy, proxy):
        s = gateway_settings(settings, via_proxy, tmp_path)
        spill = tmp_path / "pick_spill.jsonl"
        events = [pick_event(i) for i in range(6)]
        async with Bus(s.zenoh) as bus:
            async with running_gateway(s, bus) as gw:
                await proxy.cut()
                for ev in events:
                    bus.publish(CellKeys(s.cell_id).pick_events, ev)
                await wait_until(lambda: len(gw.cell.writer.buffer) == 6, 10.0, "6 picks buffered")
            # stopped with the database still down: the picks went to the spill file
            assert len([line for line in spill.read_text().splitlines() if line]) == 6
            await proxy.start()
            async with running_gateway(s, bus) as gw:
                await wait_until(
                    lambda: gw.cell.writer.written == 6, 10.0, "the 6 picks written after restart"
                )
                r = await gw.client.get("/api/v1/picks")
                assert sorted(p["pick_id"] for p in r.json()) == sorted(e.pick_id for e in events)
        assert spill.read_text() == ""
