"""/system: status, start, stop, e-stop (LLD §13.1)."""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

from fastapi import APIRouter, Body, Response

from gateway.contract import COMMAND, MUTATE
from gateway.deps import Authorized, CellDep
from gateway.schemas import CommandResult, EstopResult, StartRequest, SystemStatus
from gateway.status import cell_state_of, robot_summary, task_summary
from services.common.errors import ExecutionError, RobotBusyError

if TYPE_CHECKING:
    from gateway.state import Cell

log = logging.getLogger("pickplace.gateway.system")
router = APIRouter(prefix="/system", tags=["system"])


def cell_state(cell: Cell) -> str:
    age = None if cell.task_status_at is None else time.monotonic() - cell.task_status_at
    return cell_state_of(robot_summary(cell.hub.robot_status), task_summary(cell.hub.task_status, age))


@router.get("/status", response_model=SystemStatus)
async def get_status(cell: CellDep) -> Response:
    """The cell at a glance, from the snapshot the gateway keeps (no database query, no service asked).
    Answers even while the database or a service is down."""
    return Response(cell.status.json(), media_type="application/json")


@router.post("/start", response_model=CommandResult, dependencies=Authorized, responses=COMMAND)
async def start(cell: CellDep, body: StartRequest | None = Body(None)) -> CommandResult:
    """Start the task (relayed to the task service). 409 when it already runs or refuses to start
    (an e-stop to release first); 503 when it is unreachable."""
    req = body or StartRequest()
    status = await cell.clients.task_status(wait_for_ready=True)
    if status.running:
        raise RobotBusyError(f"the task is already running ({status.state}); stop it first")
    r = await cell.clients.start_task(req.task, req.cycles)
    if not r.success:
        raise ExecutionError(f"the task service did not start: {r.message}")
    return CommandResult(success=r.success, message=r.message)


@router.post("/stop", response_model=CommandResult, dependencies=Authorized, responses=MUTATE)
async def stop(cell: CellDep) -> CommandResult:
    """Stop the task after the current motion (relayed to the task service)."""
    r = await cell.clients.stop_task()
    return CommandResult(success=r.success, message=r.message)


@router.post("/estop", response_model=EstopResult, dependencies=Authorized, responses=MUTATE)
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


@router.post("/estop/release", response_model=CommandResult, dependencies=Authorized, responses=COMMAND)
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
