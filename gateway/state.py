"""What the running gateway holds: one :class:`Cell` per app, reached through ``request.app.state.cell``.

Its own module, importing none of the gateway's wiring (``gateway.app``, the routers, the edge), so
the routers and the edge can name it and the app can build it without an import circle.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import Coroutine
from dataclasses import dataclass, field
from typing import Any

from pickplace.v1 import common_pb2
from prometheus_client import CollectorRegistry
from sqlalchemy.ext.asyncio import AsyncEngine, AsyncSession, async_sessionmaker

from gateway.cache import ReadCache
from gateway.calibration import CalibrationRuns
from gateway.clients import CellClients
from gateway.live import LiveHub
from gateway.persist import PickWriter
from gateway.status import TASK_STATUS_FRESH_S, StatusBoard
from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.metrics import CellMetrics
from services.common.settings import Settings
from services.common.shell import ShellStateError

log = logging.getLogger("pickplace.gateway")


async def logged(coro: Coroutine[Any, Any, Any], name: str) -> None:
    """A gateway job whose failure is logged and ends only that job: the API keeps answering."""
    try:
        await coro
    except Exception as exc:  # the job's boundary: a dead loop is reported, the gateway stays up
        log.error("background task %s died: %r", name, exc, exc_info=exc)


@dataclass
class Cell:
    """What the running gateway holds; one per app, reached through ``request.app.state.cell``."""

    settings: Settings
    engine: AsyncEngine
    sessions: async_sessionmaker[AsyncSession]
    database_display: str
    hub: LiveHub
    writer: PickWriter
    clients: CellClients
    metrics: CellMetrics
    calibration: CalibrationRuns
    cache: ReadCache
    tasks: asyncio.TaskGroup | None = None  # the lifespan's; None once the gateway stops
    started_monotonic: float = field(default_factory=time.monotonic)
    task_status_at: float | None = None
    health: dict[str, Any] | None = None
    ready: asyncio.Event = field(default_factory=asyncio.Event)
    edge_port: int | None = None
    bus: Bus | None = None
    config_patch: dict[str, Any] = field(default_factory=dict)  # every change PUT /config accepted
    metrics_export: CollectorRegistry | None = None  # what /metrics renders (cell_id, robot_id on all)
    status: StatusBoard = field(init=False)
    _jobs: set[asyncio.Task[None]] = field(default_factory=set)

    def __post_init__(self) -> None:
        self.status = StatusBoard(self, self.settings.gateway.status_period_s)

    def task_running(self) -> bool:
        """The task service's last report (while fresh) says it runs."""
        if self.hub.task_status is None or self.task_status_at is None:
            return False
        fresh = time.monotonic() - self.task_status_at <= TASK_STATUS_FRESH_S
        return fresh and bool(self.hub.task_status.get("running"))

    def spawn(self, coro: Coroutine[Any, Any, Any], name: str) -> asyncio.Task[None]:
        """A background job in the gateway's task group, cancelled when the gateway stops."""
        if self.tasks is None:
            coro.close()
            raise ShellStateError(f"cannot start {name!r}: the gateway is not running")
        task = self.tasks.create_task(logged(coro, name), name=name)
        self._jobs.add(task)
        task.add_done_callback(self._jobs.discard)
        return task

    async def stop_jobs(self) -> None:
        """Cancel every background job and wait for each to finish (the first step of stopping)."""
        self.tasks = None
        jobs = list(self._jobs)
        for task in jobs:
            task.cancel()
        if jobs:
            await asyncio.wait(jobs)

    def publish_config(self, updated: list[str]) -> None:
        """Send the accepted changes to the services (they apply them to their own settings)."""
        if self.bus is None or not self.config_patch:
            return
        msg = common_pb2.ConfigUpdate(
            header=common_pb2.Header(stamp_ns=time.time_ns()),
            patch_json=json.dumps(self.config_patch, sort_keys=True),
            updated=updated,
        )
        try:
            self.bus.publish(CellKeys(self.settings.cell_id).config_updates, msg)
        except Exception as exc:  # the next periodic publication tries again
            log.warning("configuration update not published: %s", exc)

    @property
    def uptime_s(self) -> float:
        return time.monotonic() - self.started_monotonic

    @property
    def robot_id(self) -> str:
        return self.settings.gateway.robot_id
