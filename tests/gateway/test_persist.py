"""No pick lost, none stored twice: the buffer, the writer, and a real PostgreSQL outage mid-run."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Sequence
from datetime import UTC, datetime

import pytest
from pickplace.v1 import task_pb2
from sqlalchemy import func, select, text

from gateway.convert import pick_row
from gateway.db import migrate
from gateway.db.engine import make_engine, session_factory
from gateway.db.models import Pick, PickState
from gateway.db.repository import PickRepository, insert_picks
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


# ---------------------------------------------------------------------------- a row per started cycle
def cycle_event(
    pick_id: str, status: int, stage: str, *, robot_id: str = "robot_01", success: bool = False
) -> task_pb2.PickEvent:
    """One of a cycle's records as the task publishes it: running ones carry only what is known yet."""
    ev = task_pb2.PickEvent(
        pick_id=pick_id,
        robot_id=robot_id,
        status=status,
        stage_reached=stage,
        success=success,
        task="stand-rod",
    )
    ev.header.stamp_ns = time.time_ns()
    if stage not in ("INIT", "DETECT"):
        ev.object_id, ev.object_class = "rod@0.500,0.100", "rod"
    if status != task_pb2.PICK_STATUS_RUNNING:
        ev.cycle_time_s = 9.5
        if not success:
            ev.failure_reason, ev.error_code = f"{stage}: alarm 117", "ControllerError"
    return ev


RUNNING, SUCCEEDED = task_pb2.PICK_STATUS_RUNNING, task_pb2.PICK_STATUS_SUCCEEDED
FAILED, INTERRUPTED = task_pb2.PICK_STATUS_FAILED, task_pb2.PICK_STATUS_INTERRUPTED


async def _store(sessions, events: list[task_pb2.PickEvent]) -> list[str]:  # type: ignore[no-untyped-def]
    async with sessions() as s:
        done = await insert_picks(s, [pick_row(ev, "robot_01") for ev in events])
        await s.commit()
    return [p for _, p in done]


async def _rows(sessions) -> dict[str, Pick]:  # type: ignore[no-untyped-def]
    async with sessions() as s:
        return {p.pick_id: p for p in (await s.scalars(select(Pick))).all()}


async def test_a_cycle_has_its_row_from_the_start_and_keeps_its_first_outcome(database: DatabaseSettings):
    await migrate_up(database)
    engine = make_engine(database, database.url)
    sessions = session_factory(engine)
    try:
        assert await _store(sessions, [cycle_event("a", RUNNING, "INIT")]) == []  # not finished: not reported
        rows = await _rows(sessions)
        assert rows["a"].outcome == PickState.RUNNING and rows["a"].stage_reached == "INIT"
        started_at = rows["a"].timestamp
        assert await _store(sessions, [cycle_event("a", RUNNING, "GRASP")]) == []
        assert (await _rows(sessions))["a"].stage_reached == "GRASP"
        async with sessions() as s:  # the history lists picks that ended: not this one yet
            repo = PickRepository(s)
            assert await repo.count() == 0 and await repo.page(10, 0) == []
        # the outcome: reported once, the start time kept, what the cycle found kept
        assert await _store(sessions, [cycle_event("a", SUCCEEDED, "DONE", success=True)]) == ["a"]
        row = (await _rows(sessions))["a"]
        assert (row.outcome, row.success, row.stage_reached) == (PickState.SUCCEEDED, True, "DONE")
        assert row.timestamp == started_at and row.object_class == "rod" and row.cycle_time == 9.5
        # late or repeated records change nothing: a running one, an "interrupted" sent again, a duplicate
        late = [
            cycle_event("a", RUNNING, "PLACE"),
            cycle_event("a", INTERRUPTED, "PLACE"),
            cycle_event("a", SUCCEEDED, "DONE", success=True),
        ]
        assert await _store(sessions, late) == []
        assert (await _rows(sessions))["a"].stage_reached == "DONE"
        # one batch with a whole cycle in it: the outcome wins over the records before it
        batch = [
            cycle_event("b", RUNNING, "INIT"),
            cycle_event("b", RUNNING, "LIFT"),
            cycle_event("b", FAILED, "LIFT"),
        ]
        assert await _store(sessions, batch) == ["b"]
        row = (await _rows(sessions))["b"]
        assert (
            row.outcome == PickState.FAILED
            and row.error_code == "ControllerError"
            and row.object_class == "rod"
        )
        # a crash-cut cycle the task reports when it comes back: interrupted at the stage it reached
        await _store(sessions, [cycle_event("c", RUNNING, "INIT"), cycle_event("c", RUNNING, "REORIENT")])
        cut = task_pb2.PickEvent(
            pick_id="c",
            robot_id="robot_01",
            status=INTERRUPTED,
            stage_reached="REORIENT",
            failure_reason="REORIENT: interrupted: the task process ended",
            error_code="CycleInterruptedError",
        )
        assert await _store(sessions, [cut]) == ["c"]
        row = (await _rows(sessions))["c"]
        assert (row.outcome, row.stage_reached, row.success) == (PickState.INTERRUPTED, "REORIENT", False)
        assert row.object_class == "rod"  # not erased by the record that lacks it
        async with sessions() as s:
            summary = await PickRepository(s).summary(datetime.now(UTC))
        assert (summary.total, summary.succeeded, summary.failed) == (3, 1, 2)
    finally:
        await engine.dispose()


async def test_a_newer_cycle_of_the_robot_marks_its_older_running_rows_interrupted(
    database: DatabaseSettings,
):
    await migrate_up(database)
    engine = make_engine(database, database.url)
    sessions = session_factory(engine)
    try:
        # a task that died in PLACE and came back without a journal: its next cycle's start says enough
        await _store(sessions, [cycle_event("old", RUNNING, "INIT"), cycle_event("old", RUNNING, "PLACE")])
        await _store(sessions, [cycle_event("other-robot", RUNNING, "GRASP", robot_id="robot_02")])
        await _store(sessions, [cycle_event("new", RUNNING, "INIT")])
        rows = await _rows(sessions)
        assert rows["old"].outcome == PickState.INTERRUPTED and rows["old"].stage_reached == "PLACE"
        assert rows["old"].error_code == "CycleInterruptedError"
        assert (rows["old"].error_message or "").startswith("PLACE: interrupted")
        assert rows["new"].outcome == PickState.RUNNING
        assert rows["other-robot"].outcome == PickState.RUNNING  # another robot's cycle goes on
        # the restarted task's own report comes later: the row is already final, nothing changes
        assert await _store(sessions, [cycle_event("old", INTERRUPTED, "PLACE")]) == []
    finally:
        await engine.dispose()


async def test_a_cycles_own_outcome_after_a_newer_cycles_start_replaces_the_concluded_interruption(
    database: DatabaseSettings,
):
    # seen in the multi-process test: the next cycle's first record (keys.pick_progress) reached the
    # gateway before the previous cycle's outcome (keys.pick_events); the success was stored as interrupted
    await migrate_up(database)
    engine = make_engine(database, database.url)
    sessions = session_factory(engine)
    try:
        await _store(
            sessions, [cycle_event("first", RUNNING, "INIT"), cycle_event("first", RUNNING, "PLACE")]
        )
        await _store(sessions, [cycle_event("second", RUNNING, "INIT")])
        assert (await _rows(sessions))["first"].outcome == PickState.INTERRUPTED
        assert await _store(sessions, [cycle_event("first", SUCCEEDED, "DONE", success=True)]) == ["first"]
        row = (await _rows(sessions))["first"]
        assert (row.outcome, row.success, row.stage_reached) == (PickState.SUCCEEDED, True, "DONE")
        assert row.error_code is None and row.error_message is None
        # and in one batch: the outcome wins over an interruption stored with it
        batch = [cycle_event("second", INTERRUPTED, "LIFT"), cycle_event("second", FAILED, "LIFT")]
        assert await _store(sessions, batch) == ["second"]
        row = (await _rows(sessions))["second"]
        assert (row.outcome, row.error_code) == (PickState.FAILED, "ControllerError")
        # once the cycle's own outcome is stored, nothing replaces it
        assert await _store(sessions, [cycle_event("first", FAILED, "DONE")]) == []
        assert (await _rows(sessions))["first"].outcome == PickState.SUCCEEDED
    finally:
        await engine.dispose()


async def test_the_outcome_migration_keeps_stored_picks_as_they_were(database: DatabaseSettings):
    engine = make_engine(database, database.url)
    try:
        await migrate.upgrade(engine, database, "0001_initial")
        async with engine.begin() as conn:
            for i, ok in enumerate((True, False)):
                await conn.execute(
                    text(
                        "INSERT INTO picks (pick_id, timestamp, robot_id, success) "
                        f"VALUES ('p{i}', CURRENT_TIMESTAMP, 'robot_01', {'TRUE' if ok else 'FALSE'})"
                    )
                )
        assert await migrate.upgrade(engine, database) == migrate.head_revision()
        rows = await _rows(session_factory(engine))
        assert {p: r.outcome for p, r in rows.items()} == {"p0": PickState.SUCCEEDED, "p1": PickState.FAILED}
        assert await migrate.downgrade(engine, "0001_initial") == "0001_initial"
    finally:
        await engine.dispose()


class WriterTime:
    """The writer's clock and sleep, moved by the test: each backoff sleep waits until the test lets
    it end, the clock then stands that much later. A minute of outage passes in as many retries."""

    def __init__(self) -> None:
        self.now = 0.0
        self.sleeps: asyncio.Queue[tuple[float, asyncio.Future[None]]] = asyncio.Queue()

    def clock(self) -> float:
        return self.now

    async def sleep(self, seconds: float) -> None:
        done: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.sleeps.put_nowait((seconds, done))
        await done

    async def next_sleep(self, timeout_s: float = 30.0) -> asyncio.Future[None]:
        """The writer's next backoff: the clock moves past it (the test then ends it)."""
        seconds, done = await asyncio.wait_for(self.sleeps.get(), timeout_s)
        self.now += seconds
        return done


def one_cycle(k: int) -> list[task_pb2.PickEvent]:
    pick_id = f"outage-{k}"
    return [
        cycle_event(pick_id, RUNNING, "INIT"),
        cycle_event(pick_id, RUNNING, "GRASP"),
        cycle_event(
            pick_id, SUCCEEDED if k % 2 == 0 else FAILED, "DONE" if k % 2 == 0 else "LIFT", success=k % 2 == 0
        ),
    ]


@pytest.mark.integration
@pytest.mark.postgres
async def test_a_minute_without_the_database_loses_no_pick_of_the_cycles_run_meanwhile(tmp_path):
    """PostgreSQL cut off (through a proxy) for over 60 s of the writer's clock, six cycles started and
    ended during it (one started before): every cycle has its row with its outcome, none twice."""
    async with postgres_behind_proxy() as (direct, via_proxy, proxy):
        engine = make_engine(via_proxy, via_proxy.url)
        sessions = session_factory(engine)

        async def insert(events: Sequence[task_pb2.PickEvent]) -> list[tuple[int, str]]:
            async with sessions() as s:
                done = await insert_picks(s, [pick_row(ev, "robot_01") for ev in events])
                await s.commit()
            return done

        t = WriterTime()
        reported: list[str] = []
        writer = PickWriter(
            PickBuffer(4, tmp_path / "spill.jsonl"),  # a small memory bound: the outage spills to disk
            insert,
            batch_size=3,
            retry_initial_s=0.2,
            retry_max_s=5.0,
            on_written=lambda ps: reported.extend(p.event.pick_id for p in ps),
            clock=t.clock,
            sleep=t.sleep,
        )
        run = asyncio.create_task(writer.run())
        try:
            before = one_cycle(0)
            writer.offer(before[0])  # started while the database was there
            await writer.drained(15.0)
            await proxy.cut()
            for ev in before[1:]:
                writer.offer(ev)
            cycles = [before]
            spilled = 0
            while writer.database_ok or writer.outage_s() < 65.0:
                done = await t.next_sleep()  # a retry failed; the writer waits out its backoff
                if len(cycles) < 7 and t.now >= 8.0 * len(cycles):  # a cycle every 8 s of the outage
                    cycles.append(one_cycle(len(cycles)))
                    for ev in cycles[-1]:
                        writer.offer(ev)
                spilled = max(spilled, writer.buffer.spilled)
                done.set_result(None)
            assert not writer.database_ok and len(cycles) == 7 and reported == []
            assert len(writer.buffer) == 3 * 7 - 1 and spilled > 0
            await proxy.start()
            async with asyncio.timeout(60.0):
                while not writer.database_ok:  # its retries go on until one gets through
                    if t.sleeps.empty():
                        await asyncio.sleep(0.01)
                    else:
                        (await t.next_sleep()).set_result(None)
            await writer.drained(30.0)
        finally:
            run.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await run
            await engine.dispose()
        assert writer.longest_outage_s >= 60.0

        engine = make_engine(direct, PG_URL)
        try:
            rows = await _rows(session_factory(engine))
        finally:
            await engine.dispose()
    expected = {c[-1].pick_id: c[-1].status for c in cycles}
    stored = {p: r.outcome for p, r in rows.items()}
    assert stored == {
        p: PickState.SUCCEEDED if s == SUCCEEDED else PickState.FAILED for p, s in expected.items()
    }
    assert sorted(reported) == sorted(expected)  # each finished pick reported once
