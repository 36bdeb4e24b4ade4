"""/system: status, start, stop, e-stop (LLD §13.1)."""

from __future__ import annotations

import logging
import time
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Literal

from fastapi import APIRouter, Body

from gateway.db.repository import PickRepository
from gateway.deps import Authorized, CellDep
from gateway.schemas import (
    CommandResult,
    EstopResult,
    HealthSummary,
    RobotSummary,
    StartRequest,
    SystemStatus,
    TaskSummary,
)

if TYPE_CHECKING:
    from gateway.state import Cell

log = logging.getLogger("pickplace.gateway.system")
router = APIRouter(prefix="/system", tags=["system"])

# The task service publishes its status at 2 Hz; older than this and it is taken as gone.
TASK_STATUS_FRESH_S = 5.0


def _robot_summary(cell: Cell) -> RobotSummary:
    return RobotSummary(**(cell.hub.robot_status or {"connected": False, "error": "no status yet"}))


def _task_summary(cell: Cell) -> TaskSummary | None:
    if cell.hub.task_status is None or cell.task_status_at is None:
        return None
    age = time.monotonic() - cell.task_status_at
    fields = {k: v for k, v in cell.hub.task_status.items() if k in TaskSummary.model_fields}
    return TaskSummary(**fields, age_s=round(age, 3))


def _state(robot: RobotSummary, task: TaskSummary | None) -> str:
    """E-stop first; then the task's state while it reports; else whether the robot answers."""
    if robot.estop_active:
        return "ESTOP"
    if task is not None and (task.age_s or 0) <= TASK_STATUS_FRESH_S:
        return task.state or "UNKNOWN"
    return "IDLE" if robot.connected else "OFFLINE"


def cell_state(cell: Cell) -> str:
    return _state(_robot_summary(cell), _task_summary(cell))


@router.get("/status", response_model=SystemStatus)
async def get_status(cell: CellDep) -> SystemStatus:
    """The cell at a glance. Answers even while the database or a service is down."""
    robot, task = _robot_summary(cell), _task_summary(cell)
    state = _state(robot, task)
    picks_today, success_rate = 0, None
    db_state: Literal["ok", "unavailable"] = "ok"
    try:

        async def today() -> tuple[int, int]:
            async with cell.sessions() as s:
                return await PickRepository(s).today(datetime.now(UTC))

        total, ok = await cell.cache.get(("today",), today)
        picks_today, success_rate = total, (ok / total if total else None)
    except Exception as exc:  # the status page must not go dark with the database
        log.debug("status without database: %s", exc)
        db_state = "unavailable"
    if not cell.writer.database_ok:
        db_state = "unavailable"
    return SystemStatus(
        state=state,
        uptime=round(cell.uptime_s, 3),
        picks_today=picks_today,
        success_rate=success_rate,
        task=task,
        robot=robot,
        database=db_state,
        pick_buffer=len(cell.writer.buffer),
        health=HealthSummary(**cell.health) if cell.health else None,
    )


@router.post("/start", response_model=CommandResult, dependencies=Authorized)
async def start(cell: CellDep, body: StartRequest | None = Body(None)) -> CommandResult:
    """Start the task (relayed to the task service; 503 when it is unreachable)."""
    req = body or StartRequest()
    r = await cell.clients.start_task(req.task, req.cycles)
    return CommandResult(success=r.success, message=r.message)


@router.post("/stop", response_model=CommandResult, dependencies=Authorized)
async def stop(cell: CellDep) -> CommandResult:
    """Stop the task after the current motion (relayed to the task service)."""
    r = await cell.clients.stop_task()
    return CommandResult(success=r.success, message=r.message)


@router.post("/estop", response_model=EstopResult, dependencies=Authorized)
async def estop(cell: CellDep) -> EstopResult:
    """Emergency stop: straight to the robot driver on its own channel; the task service is told too."""
    t0 = time.perf_counter()
    r = await cell.clients.emergency_stop(
        on_task_result=lambda text: cell.hub.on_event("estop_task", {"message": text})
    )
    latency_ms = (time.perf_counter() - t0) * 1e3
    cell.metrics.estop.labels(cell.robot_id, "rest").inc()
    cell.hub.on_event("estop", {"message": r.message, "latency_ms": round(latency_ms, 3)})
    cell.spawn(_refresh_robot_status(cell), "gateway-estop-status")
    log.warning("e-stop pressed over REST (%.1f ms): %s", latency_ms, r.message)
    return EstopResult(success=r.success, message=r.message, latency_ms=latency_ms)


@router.post("/estop/release", response_model=CommandResult, dependencies=Authorized)
async def estop_release(cell: CellDep) -> CommandResult:
    """Release the software e-stop, clear the alarms and enable the arm (not in the LLD; the dashboard's reset)."""
    await cell.clients.release_estop()
    await _refresh_robot_status(cell)
    return CommandResult(success=True, message="e-stop released, alarms cleared, arm enabled")


async def _refresh_robot_status(cell: Cell) -> None:
    asked = time.monotonic()
    try:
        cell.hub.on_robot_status(await cell.clients.robot_status(), asked_at=asked)
    except Exception as exc:
        cell.hub.on_robot_status(None, str(exc), asked_at=asked)
