"""Gateway fixtures: databases (SQLite file, PostgreSQL in a throw-away schema), a running gateway,
a Zenoh publisher, and a scripted TaskController standing in for the task service (a later issue).

PostgreSQL tests skip with a reason when the server at 127.0.0.1:5432 is not reachable, and FAIL
instead when ``PICKPLACE_REQUIRE_POSTGRES=1`` (CI sets it).
"""

from __future__ import annotations

import asyncio
import os
import time
import uuid
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import httpx
import pytest
from pickplace.v1 import common_pb2, task_pb2, task_pb2_grpc

from gateway.app import create_app
from gateway.db import migrate
from gateway.db.engine import make_engine
from gateway.server import GatewayServer
from services.common import grpc_util
from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.modes import TaskKind
from services.common.settings import DatabaseSettings, Settings
from tests.conftest import free_port

PG_URL = os.environ.get("PICKPLACE_TEST_POSTGRES_URL", "postgresql+asyncpg://postgres@127.0.0.1:5432/test")
TOKEN = "test-token-0123456789abcdef"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


async def postgres_unreachable() -> str | None:
    import asyncpg

    dsn = PG_URL.replace("postgresql+asyncpg://", "postgresql://")
    try:
        conn = await asyncpg.connect(dsn, timeout=3)
    except Exception as exc:
        return f"{type(exc).__name__}: {exc}"
    await conn.close()
    return None


async def require_postgres() -> None:
    why = await postgres_unreachable()
    if why is None:
        return
    msg = f"PostgreSQL at {PG_URL} unreachable ({why})"
    if os.environ.get("PICKPLACE_REQUIRE_POSTGRES") == "1":
        pytest.fail(msg + " and PICKPLACE_REQUIRE_POSTGRES=1")
    pytest.skip(msg + "; set PICKPLACE_REQUIRE_POSTGRES=1 to make this a failure")


@asynccontextmanager
async def postgres_schema() -> AsyncIterator[str]:
    """A fresh schema for one test; dropped afterwards (only the schema this created)."""
    import asyncpg

    await require_postgres()
    schema = f"gw_test_{uuid.uuid4().hex[:12]}"
    dsn = PG_URL.replace("postgresql+asyncpg://", "postgresql://")
    conn = await asyncpg.connect(dsn, timeout=5)
    try:
        await conn.execute(f'CREATE SCHEMA "{schema}"')
        yield schema
    finally:
        await conn.execute(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE')
        await conn.close()


@pytest.fixture(params=["sqlite", "postgres"])
async def database(request, tmp_path) -> AsyncIterator[DatabaseSettings]:  # type: ignore[no-untyped-def]
    """Unmigrated database settings, on each backend."""
    if request.param == "sqlite":
        yield DatabaseSettings(url=f"sqlite+aiosqlite:///{tmp_path / 'gateway.db'}")
    else:
        async with postgres_schema() as schema:
            yield DatabaseSettings(url=PG_URL, schema_name=schema)


@pytest.fixture
async def sqlite_db(tmp_path) -> DatabaseSettings:  # type: ignore[no-untyped-def]
    return DatabaseSettings(url=f"sqlite+aiosqlite:///{tmp_path / 'gateway.db'}")


@pytest.fixture
async def postgres_db() -> AsyncIterator[DatabaseSettings]:
    async with postgres_schema() as schema:
        yield DatabaseSettings(url=PG_URL, schema_name=schema)


async def migrate_up(db: DatabaseSettings) -> None:
    engine = make_engine(db, db.url)
    try:
        await migrate.upgrade(engine, db)
    finally:
        await engine.dispose()


def gateway_settings(settings: Settings, db: DatabaseSettings, tmp_path, **gateway: Any) -> Settings:  # type: ignore[no-untyped-def]
    gw = settings.gateway.model_copy(
        update={
            "api_token": _secret(TOKEN),
            "pick_spill_file": str(tmp_path / "pick_spill.jsonl"),
            "edge_grpc_port": None,
            "db_retry_initial_s": 0.05,
            "db_retry_max_s": 0.3,
            "robot_status_period_s": 0.2,
            **gateway,
        }
    )
    # a free port for the (fake) task service, and none for the robot driver unless a test starts one
    robot_port = settings.grpc.robot_port or free_port()
    grpc = settings.grpc.model_copy(update={"task_port": free_port(), "robot_port": robot_port})
    return settings.model_copy(update={"database": db, "gateway": gw, "grpc": grpc})


def _secret(v: str) -> Any:
    from pydantic import SecretStr

    return SecretStr(v)


@dataclass
class RunningGateway:
    server: GatewayServer
    client: httpx.AsyncClient
    settings: Settings

    @property
    def cell(self) -> Any:
        return self.server.app.state.cell


@asynccontextmanager
async def running_gateway(
    settings: Settings, bus: Bus | None = None, **kw: Any
) -> AsyncIterator[RunningGateway]:
    app = create_app(settings, bus=bus, **kw)
    async with (
        GatewayServer(app, "127.0.0.1", 0) as server,
        httpx.AsyncClient(base_url=server.url, timeout=10.0) as client,
    ):
        yield RunningGateway(server, client, settings)


def pick_event(
    i: int,
    *,
    success: bool = True,
    robot_id: str = "robot_01",
    stamp_ns: int | None = None,
    pick_id: str | None = None,
) -> task_pb2.PickEvent:
    ev = task_pb2.PickEvent(
        header=common_pb2.Header(stamp_ns=stamp_ns if stamp_ns is not None else time.time_ns()),
        pick_id=pick_id or uuid.uuid4().hex,
        robot_id=robot_id,
        object_id=f"obj{i}",
        object_class="rod" if i % 2 == 0 else "cube_red",
        pick_pose=common_pb2.Pose(x=0.45, y=0.01 * i, z=0.02, qw=1.0),
        place_pose=common_pb2.Pose(x=0.45, y=0.0, z=0.1, qx=0.7071068, qw=0.7071068),
        grasp_quality=0.8,
        cycle_time_s=8.0 + 0.1 * i,
        success=success,
        stage_reached="DONE" if success else "GRASP",
        failure_reason="" if success else "object slipped during LIFT",
        error_code="" if success else "GraspFailureError",
        attempts=1,
        task=TaskKind.STAND_ROD,
    )
    ev.stage_durations_s.update({"DETECT": 0.4, "PLAN": 0.6, "APPROACH": 2.0})
    return ev


async def wait_until(predicate, timeout_s: float, what: str, interval_s: float = 0.02) -> None:  # type: ignore[no-untyped-def]
    """Poll ``predicate`` (sync or async) until true; fail naming ``what`` after the deadline."""
    deadline = time.monotonic() + timeout_s
    while True:
        result = predicate()
        if asyncio.iscoroutine(result):
            result = await result
        if result:
            return
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s}s waiting for {what}")
        await asyncio.sleep(interval_s)


# ------------------------------------------------------------------ a scripted task service
@dataclass
class FakeTaskController(task_pb2_grpc.TaskControllerServicer):
    """Stands in for the task service: Start publishes a status sequence and one pick per cycle."""

    bus: Bus | None
    cell_id: str
    cycle_s: float = 0.3
    starts: list[tuple[str, int]] = field(default_factory=list)
    stops: int = 0
    estops: int = 0
    estop_event: asyncio.Event = field(default_factory=asyncio.Event)
    running: bool = False
    published: list[str] = field(default_factory=list)
    _runner: asyncio.Task[None] | None = None

    async def Start(self, request, context):  # type: ignore[no-untyped-def]
        self.starts.append((request.task, request.cycles))
        if self.running:
            return common_pb2.CommandResponse(success=False, message="already running")
        self.running = True
        self._runner = asyncio.create_task(self._run(request.task or TaskKind.STAND_ROD, request.cycles or 1))
        return common_pb2.CommandResponse(success=True, message=f"started {request.task or 'stand-rod'}")

    async def Stop(self, request, context):  # type: ignore[no-untyped-def]
        self.stops += 1
        self.running = False
        return common_pb2.CommandResponse(success=True, message="stopping after this motion")

    async def EmergencyStop(self, request, context):  # type: ignore[no-untyped-def]
        self.estops += 1
        self.running = False
        self.estop_event.set()
        return common_pb2.CommandResponse(success=True, message="task e-stopped")

    async def GetStatus(self, request, context):  # type: ignore[no-untyped-def]
        return task_pb2.TaskStatus(state="IDLE" if not self.running else "PLAN", running=self.running)

    async def _run(self, task: str, cycles: int) -> None:
        keys = CellKeys(self.cell_id)
        for cycle in range(1, cycles + 1):
            for k, state in enumerate(
                ("DETECT", "PLAN", "APPROACH", "GRASP", "LIFT", "PLACE", "RELEASE", "DONE")
            ):
                if not self.running:
                    return
                if self.bus is not None:
                    self.bus.publish(
                        keys.task_status,
                        task_pb2.TaskStatus(
                            state=state,
                            progress=(k + 1) / 8,
                            task=task,
                            running=True,
                            cycle_index=cycle,
                            picks_completed=cycle - 1,
                        ),
                    )
                await asyncio.sleep(self.cycle_s / 8)
            ev = pick_event(cycle)
            ev.task = task
            if self.bus is not None:
                self.bus.publish(keys.pick_events, ev)
            self.published.append(ev.pick_id)
        self.running = False
        if self.bus is not None:
            self.bus.publish(
                keys.task_status,
                task_pb2.TaskStatus(
                    state="IDLE", progress=0, task=task, running=False, picks_completed=cycles
                ),
            )


@asynccontextmanager
async def fake_task_service(bus: Bus | None, cell_id: str, port: int) -> AsyncIterator[FakeTaskController]:
    servicer = FakeTaskController(bus, cell_id)
    server = grpc_util.create_server()
    task_pb2_grpc.add_TaskControllerServicer_to_server(servicer, server)
    grpc_util.bind(server, "127.0.0.1", port)
    await server.start()
    try:
        yield servicer
    finally:
        if servicer._runner is not None:
            servicer._runner.cancel()
        await server.stop(grace=0.2)
