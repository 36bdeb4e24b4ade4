"""GET /system/status comes from a snapshot: no database query and no service asked per request."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pytest
from sqlalchemy import event

from gateway.live import LiveHub
from gateway.status import StatusBoard
from tests.gateway.conftest import gateway_settings, migrate_up, pick_event, running_gateway, wait_until


@dataclass
class FakeWriter:
    database_ok: bool = True
    buffer: list[Any] = field(default_factory=list)


@dataclass
class FakeCell:
    hub: LiveHub = field(default_factory=LiveHub)
    writer: FakeWriter = field(default_factory=FakeWriter)
    task_status_at: float | None = None
    started_monotonic: float = 0.0
    health: dict[str, Any] | None = None


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_the_snapshot_is_rebuilt_on_change_or_age_never_per_request() -> None:
    clock = Clock()
    cell = FakeCell()
    board = StatusBoard(cell, period_s=0.1, clock=clock)
    first = board.json()
    for _ in range(1000):
        assert board.json() is first
    assert board.builds == 1
    assert board.model().state == "OFFLINE" and board.model().uptime == 100.0

    clock.t += 0.25  # uptime moves: one rebuild
    assert board.json() is not first and board.builds == 2 and board.model().uptime == 100.25

    cell.hub.on_change = lambda _kind: board.invalidate()
    from pickplace.v1 import robot_pb2

    cell.hub.on_robot_status(robot_pb2.RobotStatus(connected=True, estop_active=True), asked_at=clock.t)
    assert board.model().state == "ESTOP" and board.builds == 3  # a change shows at once


async def test_status_requests_query_nothing(settings, sqlite_db, tmp_path) -> None:  # type: ignore[no-untyped-def]
    await migrate_up(sqlite_db)
    s = gateway_settings(settings, sqlite_db, tmp_path, status_db_period_s=60.0, health_period_s=3600.0)
    async with running_gateway(s) as gw:
        cell = gw.cell
        await wait_until(lambda: cell.status.counted, 10, "the refresher's first count")
        queries: list[str] = []

        def count(_conn, _cursor, statement, *_args) -> None:  # type: ignore[no-untyped-def]
            queries.append(statement)

        event.listen(cell.engine.sync_engine, "before_cursor_execute", count)
        try:
            for _ in range(200):
                r = await gw.client.get("/api/v1/system/status")
                assert r.status_code == 200 and r.headers["content-type"] == "application/json"
                assert r.headers["x-content-type-options"] == "nosniff"
            assert r.headers["cache-control"] == "no-store"
            head = await gw.client.head("/api/v1/system/status")
            assert head.status_code == 200 and head.content == b""
            # with an Origin header it goes through the middleware (CORS) and the route: the same answer
            routed = await gw.client.get("/api/v1/system/status", headers={"Origin": "http://127.0.0.1"})
            assert routed.status_code == 200 and routed.json()["state"] == r.json()["state"]
            assert routed.headers["x-content-type-options"] == "nosniff"
            assert queries == [], queries[:3]
            body = r.json()
            assert body["picks_today"] == 0 and body["database"] == "ok"

            # picks written: the snapshot's counts follow (one query by the refresher, not by a request)
            cell.writer.offer(pick_event(1))
            await wait_until(
                lambda: cell.status.picks_today == 1, 10, "the snapshot to count the written pick"
            )
            r = await gw.client.get("/api/v1/system/status")
            assert r.json()["picks_today"] == 1 and r.json()["success_rate"] == 1.0
            assert len(queries) >= 1
        finally:
            event.remove(cell.engine.sync_engine, "before_cursor_execute", count)


pytestmark = pytest.mark.integration


def test_the_counts_are_read_again_at_midnight_utc() -> None:
    from datetime import UTC, datetime

    from gateway.app import seconds_to_midnight_utc

    assert seconds_to_midnight_utc(datetime(2026, 12, 1, 23, 59, 59, tzinfo=UTC)) == 1.5
    assert seconds_to_midnight_utc(datetime(2026, 12, 31, 0, 0, 0, tzinfo=UTC)) == 86_400.5


def test_a_message_is_serialised_once_for_every_dashboard() -> None:
    from pickplace.v1 import robot_pb2

    hub = LiveHub()
    with hub.connection() as a, hub.connection() as b:
        assert a.get_nowait() == b.get_nowait() == '{"type":"timeline","data":[]}'  # nothing happened yet
        hub.on_robot_status(robot_pb2.RobotStatus(connected=True, robot_mode=5), asked_at=1.0)
        ta, tb = a.get_nowait(), b.get_nowait()
    assert ta is tb and '"robot_mode":5' in ta
