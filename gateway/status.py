"""``GET /system/status`` from a snapshot: the answer is rendered once and served as bytes.

The snapshot is rebuilt when what it shows changes (the hub reports a new task or robot status, an
e-stop, picks written) or when it is older than ``gateway.status_period_s`` (uptime and ages move),
never per request. The database's share (picks today, success rate) is read by a background job
every ``gateway.status_db_period_s`` and after each batch of picks is written; a request never
queries the database, never asks a service.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any, Literal, Protocol

from starlette.types import Scope, Send

from gateway.live import LiveHub
from gateway.persist import PickWriter
from gateway.schemas import HealthSummary, RobotSummary, SystemStatus, TaskSummary
from gateway.security import SECURITY_HEADERS

log = logging.getLogger("pickplace.gateway.status")

# The task service publishes its status at 2 Hz; older than this and it is taken as gone.
TASK_STATUS_FRESH_S = 5.0


def robot_summary(robot_status: dict[str, Any] | None) -> RobotSummary:
    return RobotSummary(**(robot_status or {"connected": False, "error": "no status yet"}))


def task_summary(task_status: dict[str, Any] | None, age_s: float | None) -> TaskSummary | None:
    if task_status is None or age_s is None:
        return None
    fields = {k: v for k, v in task_status.items() if k in TaskSummary.model_fields}
    return TaskSummary(**fields, age_s=round(age_s, 3))


def cell_state_of(robot: RobotSummary, task: TaskSummary | None) -> str:
    """E-stop first; then the task's state while it reports; else whether the robot answers."""
    if robot.estop_active:
        return "ESTOP"
    if task is not None and (task.age_s or 0) <= TASK_STATUS_FRESH_S:
        return task.state or "UNKNOWN"
    return "IDLE" if robot.connected else "OFFLINE"


class StatusSource(Protocol):
    """What the snapshot is made of (the gateway's ``Cell``)."""

    hub: LiveHub
    writer: PickWriter
    task_status_at: float | None
    started_monotonic: float
    health: dict[str, Any] | None


class StatusBoard:
    """The status snapshot of one gateway. ``clock`` is monotonic seconds (injected in tests)."""

    def __init__(self, cell: StatusSource, period_s: float, clock: Callable[[], float] = time.monotonic):
        self.cell = cell
        self.period_s = period_s
        self.clock = clock
        self.picks_today = 0
        self.succeeded_today = 0
        self.database_ok = True
        self.counted = False  # today's picks read at least once
        self.builds = 0
        self._json: bytes | None = None
        self._model: SystemStatus | None = None
        self._built_at = 0.0

    def invalidate(self) -> None:
        self._json = None

    def model(self) -> SystemStatus:
        self._current()
        assert self._model is not None
        return self._model

    def json(self) -> bytes:
        return self._current()

    def _current(self) -> bytes:
        now = self.clock()
        if self._json is None or now - self._built_at >= self.period_s:
            self._model = self._build(now)
            self._json = self._model.model_dump_json().encode()
            self._built_at = now
            self.builds += 1
        return self._json

    def _build(self, now: float) -> SystemStatus:
        cell = self.cell
        robot = robot_summary(cell.hub.robot_status)
        age = None if cell.task_status_at is None else now - cell.task_status_at
        task = task_summary(cell.hub.task_status, age)
        db: Literal["ok", "unavailable"] = (
            "ok" if self.database_ok and cell.writer.database_ok else "unavailable"
        )
        total, ok = self.picks_today, self.succeeded_today
        return SystemStatus(
            state=cell_state_of(robot, task),
            uptime=round(now - cell.started_monotonic, 3),
            picks_today=total,
            success_rate=ok / total if total else None,
            task=task,
            robot=robot,
            database=db,
            pick_buffer=len(cell.writer.buffer),
            health=HealthSummary(**cell.health) if cell.health else None,
        )

    async def refresh_counts(self, today: Callable[[], Awaitable[tuple[int, int]]]) -> None:
        """Read today's picks (one query); the snapshot shows the database as unavailable on failure."""
        try:
            self.picks_today, self.succeeded_today = await today()
            self.database_ok = self.counted = True
        except Exception as exc:  # the status must not go dark with the database
            log.debug("status without database: %s", exc)
            self.database_ok = False
        self.invalidate()


def fast_status_request(scope: Scope) -> bool:
    """A plain ``GET``/``HEAD`` the snapshot answers (one with an ``Origin`` goes the long way, via CORS)."""
    return scope["method"] in ("GET", "HEAD") and not any(k == b"origin" for k, _ in scope["headers"])


async def send_status(board: StatusBoard, scope: Scope, send: Send) -> None:
    """The snapshot's bytes as the response, with the headers every API answer carries."""
    body = board.json()
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        (b"cache-control", b"no-store"),
        *SECURITY_HEADERS.items(),
    ]
    await send({"type": "http.response.start", "status": 200, "headers": headers})
    await send({"type": "http.response.body", "body": b"" if scope["method"] == "HEAD" else body})
