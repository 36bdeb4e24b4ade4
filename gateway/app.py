"""The FastAPI application: built by :func:`create_app`, wired in its lifespan.

Nothing is built at import time: settings come in as an argument; the engine, the Zenoh
feeds, the gRPC clients, the pick writer and the background loops are created when the app
starts and closed when it stops. Routers reach them through dependencies (``gateway.deps``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from datetime import UTC, datetime, timedelta
from pathlib import Path

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from pickplace.v1 import common_pb2, robot_pb2, task_pb2
from prometheus_client import CollectorRegistry
from sqlalchemy.ext.asyncio import AsyncEngine, AsyncSession, async_sessionmaker
from starlette.types import Receive, Scope, Send

from gateway import errors as rest_errors
from gateway import health as health_mod
from gateway.cache import ReadCache
from gateway.calibration import CalibrationExecutor, CalibrationRuns
from gateway.clients import CellClients
from gateway.convert import pick_row, validate_pick_event
from gateway.db import migrate
from gateway.db.engine import database_url, make_engine, redact, session_factory
from gateway.db.repository import HealthRepository, PickRepository, insert_picks
from gateway.feeds import BusFeeds
from gateway.live import LiveHub
from gateway.persist import PickBuffer, PickWriter, WrittenPick
from gateway.records import pick_json
from gateway.security import BodySizeLimit, SecurityHeaders
from gateway.state import Cell
from gateway.status import fast_status_request, send_status
from services.common.bus import Bus
from services.common.errors import ConfigurationError, InvalidInputError, RobotError
from services.common.keys import CellKeys
from services.common.metrics import CellMetrics, labelled_registry
from services.common.settings import REPO_ROOT, Settings

log = logging.getLogger("pickplace.gateway")

API_PREFIX = "/api/v1"
CONFIG_REPUBLISH_S = 5.0  # how soon a restarted service catches up with PUT /config changes


def repo_path(path: str) -> Path:
    p = Path(path)
    return p if p.is_absolute() else REPO_ROOT / p


async def _prepare_database(settings: Settings) -> tuple[AsyncEngine, str]:
    url = database_url(settings.database)
    display = redact(url)
    engine = make_engine(settings.database, url)
    try:
        if settings.database.auto_migrate:
            rev = await migrate.upgrade(engine, settings.database)
            log.info("database %s at revision %s", display, rev)
        else:
            await migrate.require_head(engine, display)
    except ConfigurationError:
        await engine.dispose()
        raise
    except Exception as exc:
        await engine.dispose()
        raise ConfigurationError(f"cannot use database {display}: {type(exc).__name__}: {exc}") from exc
    return engine, display


def _insert_fn(
    sessions: async_sessionmaker[AsyncSession], robot_id: str
) -> Callable[[Sequence[task_pb2.PickEvent]], Awaitable[list[tuple[int, str]]]]:
    async def insert(events: Sequence[task_pb2.PickEvent]) -> list[tuple[int, str]]:
        rows = [pick_row(ev, robot_id) for ev in events]
        async with sessions() as s:
            new = await insert_picks(s, rows)
            await s.commit()
        return new

    return insert


async def _poll_robot_status(cell: Cell) -> None:
    period = cell.settings.gateway.robot_status_period_s
    while True:
        asked = time.monotonic()
        try:
            st = await cell.clients.robot_status()
            cell.hub.on_robot_status(st, asked_at=asked)
            cell.metrics.robot_mode.labels(cell.robot_id).set(st.robot_mode)
        except RobotError as exc:
            cell.hub.on_robot_status(None, str(exc), asked_at=asked)
        await asyncio.sleep(period)


async def _status_counts(cell: Cell, written: asyncio.Event) -> None:
    """Today's picks for the status snapshot: after picks are written, at midnight UTC, and every
    status_db_period_s besides (a query holds the event loop for milliseconds: not every second)."""

    async def today() -> tuple[int, int]:
        async with cell.sessions() as s:
            return await PickRepository(s).today(datetime.now(UTC))

    while True:
        await cell.status.refresh_counts(today)
        written.clear()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(
                min(cell.settings.gateway.status_db_period_s, seconds_to_midnight_utc(datetime.now(UTC)))
            ):
                await written.wait()


def seconds_to_midnight_utc(now: datetime) -> float:
    """Until the next midnight UTC (when today's picks start from 0), plus a moment."""
    midnight = datetime(now.year, now.month, now.day, tzinfo=UTC) + timedelta(days=1)
    return (midnight - now).total_seconds() + 0.5


async def _republish_config(cell: Cell) -> None:
    """Repeat the accepted changes now and then, for a service that (re)started after the PUT."""
    while True:
        await asyncio.sleep(CONFIG_REPUBLISH_S)
        cell.publish_config([])


async def _sample_health(cell: Cell) -> None:
    period = cell.settings.gateway.health_period_s
    disk = repo_path("var")
    disk.mkdir(parents=True, exist_ok=True)
    health_mod.sample(disk, with_gpu=False)  # primes psutil's CPU counter
    while True:
        await asyncio.sleep(period)
        values = await asyncio.to_thread(health_mod.sample, disk)
        now = datetime.now(UTC)
        cell.health = {"timestamp": now, **values}
        try:
            async with cell.sessions() as s:
                await HealthRepository(s).add(cell.robot_id, values, now)
                await s.commit()
        except Exception as exc:  # health samples are not precious; picks are
            log.warning("system health sample not stored: %s", str(exc).splitlines()[0])


class GatewayApp(FastAPI):
    """The FastAPI app, with ``GET /system/status`` answered from the snapshot before anything else:
    no middleware layer, routing, dependency or validation between the socket and the bytes, so a
    status request costs the least the event loop can spend on it. The route of the same path
    stays (the OpenAPI document, and a request with an ``Origin`` header, which CORS must see)."""

    status_path = f"{API_PREFIX}/system/status"

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["path"] == self.status_path and fast_status_request(scope):
            cell: Cell | None = getattr(self.state, "cell", None)
            if cell is not None:  # None: the app has not started yet
                await send_status(cell.status, scope, send)
                return
        await super().__call__(scope, receive, send)


def create_app(
    settings: Settings,
    *,
    bus: Bus | None = None,
    calibration_executor: CalibrationExecutor | None = None,
    serve_web: bool = True,
    metrics_registries: Sequence[CollectorRegistry] = (),
) -> FastAPI:
    """The gateway app. ``bus``: an open Zenoh bus to share (the embedded run); else it opens its own.
    ``metrics_registries``: other services' registries in this process, exported at /metrics too."""
    gw = settings.gateway
    if gw.api_token is None:
        raise ConfigurationError(
            "gateway.api_token is not set: set PICKPLACE_GATEWAY__API_TOKEN (at least 16 characters); "
            "only the embedded `pickplace up` generates one"
        )

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        try:
            engine, display = await _prepare_database(settings)
        except Exception as exc:
            app.state.startup_error = exc  # GatewayServer re-raises it with its message
            raise
        sessions = session_factory(engine)
        metrics = CellMetrics()
        hub = LiveHub(gw.joint_state_rate_hz)
        spill = repo_path(gw.pick_spill_file) if gw.pick_spill_file else None
        buffer = PickBuffer(gw.pick_buffer_size, spill)
        cache = ReadCache(ttl_s=2.0)
        picks_written = asyncio.Event()

        def on_written(picks: list[WrittenPick]) -> None:
            cache.clear()
            picks_written.set()
            for p in picks:
                ev = p.event
                metrics.observe_pick(
                    gw.robot_id,  # the configured robot, whatever the event names (the task names its cell)
                    ev.object_class,
                    ev.success,
                    ev.cycle_time_s,
                    ev.grasp_quality or None,
                    ev.stage_reached,
                )
            metrics.picks_persisted.inc(len(picks))
            metrics.pick_buffer_depth.set(len(buffer))
            hub.on_picks([pick_json(p.id, p.event, gw.robot_id) for p in picks])

        writer = PickWriter(
            buffer,
            _insert_fn(sessions, gw.robot_id),
            batch_size=gw.pick_batch_size,
            retry_initial_s=gw.db_retry_initial_s,
            retry_max_s=gw.db_retry_max_s,
            on_written=on_written,
        )
        own_bus = bus is None
        the_bus = bus if bus is not None else Bus(settings.zenoh)
        feeds: BusFeeds | None = None
        async with contextlib.AsyncExitStack() as stack:
            stack.push_async_callback(engine.dispose)
            clients = await stack.enter_async_context(CellClients(settings))
            calibration = CalibrationRuns(calibration_executor, sessions, gw.robot_id)
            stack.push_async_callback(calibration.close)
            cell = Cell(
                settings, engine, sessions, display, hub, writer, clients, metrics, calibration, cache
            )
            app.state.cell = cell
            cell.metrics_export = labelled_registry(
                metrics.registry, cell_id=settings.cell_id, robot_id=gw.robot_id, extra=metrics_registries
            )
            hub.on_change = lambda _kind: cell.status.invalidate()
            app.state.api_token = gw.api_token.get_secret_value() if gw.api_token else ""

            def on_pick_event(ev: task_pb2.PickEvent) -> None:
                try:
                    validate_pick_event(ev)
                except InvalidInputError as exc:
                    writer.rejected += 1
                    log.error("pick event refused: %s", exc)
                    return
                writer.offer(ev)
                metrics.pick_buffer_depth.set(len(buffer))

            def on_task_status(msg: task_pb2.TaskStatus) -> None:
                cell.task_status_at = time.monotonic()
                hub.on_task_status(msg)

            def on_joint_state(msg: common_pb2.JointState) -> None:
                if hub.on_joint_state(msg):
                    metrics.set_joint_positions(gw.robot_id, msg.name, msg.position)

            def on_robot_status(st: robot_pb2.RobotStatus) -> None:
                hub.on_robot_status(st)

            if own_bus:
                await the_bus.__aenter__()
                stack.push_async_callback(the_bus.__aexit__, None, None, None)
            feeds = BusFeeds(
                the_bus,
                CellKeys(settings.cell_id),
                on_task_status=on_task_status,
                on_joint_state=on_joint_state,
                on_robot_status=on_robot_status,
                on_pick_event=on_pick_event,
                on_camera=hub.on_camera,
                on_detections=hub.on_detections,
                on_frame=hub.on_frame,
                on_plan=hub.on_plan,
            )
            feeds.start()
            stack.callback(feeds.close)
            cell.bus = the_bus

            if gw.edge_grpc_port is not None:
                from gateway.edge import EdgeServer
                from gateway.routers.system import cell_state

                edge = EdgeServer(
                    cell, gw.host, gw.edge_grpc_port, app.state.api_token, lambda: cell_state(cell)
                )
                cell.edge_port = (await stack.enter_async_context(edge)).grpc_port

            # the gateway's background work: one task group, its jobs cancelled before anything closes
            cell.tasks = await stack.enter_async_context(asyncio.TaskGroup())

            async def stop_tasks() -> None:
                # hear nothing more, then let the samples already handed to the loop reach the buffer
                if feeds is not None:
                    feeds.close()
                await asyncio.sleep(0)
                await cell.stop_jobs()
                # last chance to write what is buffered, then keep the rest on disk for the next start
                if len(buffer):
                    with contextlib.suppress(Exception):
                        await writer.flush(timeout_s=2.0)
                    n = writer.shutdown()
                    if n:
                        log.warning("%d pick event(s) kept in %s for the next start", n, buffer.spill_path)

            stack.push_async_callback(stop_tasks)
            for name, coro in (
                ("gateway-pick-writer", writer.run()),
                ("gateway-robot-status", _poll_robot_status(cell)),
                ("gateway-health", _sample_health(cell)),
                ("gateway-config", _republish_config(cell)),
                ("gateway-status-counts", _status_counts(cell, picks_written)),
            ):
                cell.spawn(coro, name)
            log.info("gateway ready: database %s, cell %s", display, settings.cell_id)
            cell.ready.set()
            app.state.ready.set()
            yield

    app = GatewayApp(
        title="pickplace gateway",
        version="1.0.0",
        description="REST API of the pickplace cell (LLD §13.1). Mutating requests need a bearer token.",
        lifespan=lifespan,
        generate_unique_id_function=lambda route: route.name,  # operationIds the links name
    )
    app.state.ready = asyncio.Event()
    app.state.startup_error = None
    rest_errors.install(app)
    from gateway.routers import calibration, config, live, picks, prometheus, system, web
    from gateway.routers import metrics as metrics_router

    for r in (
        system.router,
        picks.router,
        metrics_router.router,
        calibration.router,
        config.router,
        live.router,
    ):
        app.include_router(r, prefix=API_PREFIX)
    app.include_router(prometheus.router)
    if serve_web:
        web.mount(app, repo_path(gw.web_dir), settings)

    app.add_middleware(SecurityHeaders, api_prefix=API_PREFIX)
    if gw.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=gw.cors_origins,
            allow_methods=["GET", "POST", "PUT"],
            allow_headers=["Authorization", "Content-Type"],
        )
    app.add_middleware(BodySizeLimit, max_bytes=gw.max_request_bytes)
    return app
