"""/calibration: start a hand-eye calibration run, follow its progress (LLD §13.1)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, HTTPException, Path

from gateway.calibration import CalibrationRun
from gateway.contract import COMMAND, READ_DB, calibration_links, errors
from gateway.convert import as_utc
from gateway.deps import Authorized, CellDep
from gateway.schemas import CalibrationRequest, CalibrationStarted, CalibrationView
from services.common.errors import RobotBusyError

router = APIRouter(prefix="/calibration", tags=["calibration"])


@router.post(
    "/handshake",
    response_model=CalibrationStarted,
    status_code=202,
    dependencies=Authorized,
    responses={**COMMAND, 202: {"links": calibration_links()}},
)
async def start_calibration(
    cell: CellDep, body: CalibrationRequest | None = Body(None)
) -> CalibrationStarted:
    """Start a hand-eye calibration run; poll ``GET /calibration/{id}`` for progress and result.

    409 while the task runs (the arm is the task's), while another run is going, or when no
    calibration routine is connected to this gateway."""
    if cell.task_running():
        raise RobotBusyError("stop the task before calibrating: the arm is busy picking")
    num_poses = body.num_poses if body is not None else cell.settings.vision.calibration.n_poses
    run = await cell.calibration.start(num_poses)
    return CalibrationStarted(calibration_id=run.run_id)


def _view(run: CalibrationRun) -> CalibrationView:
    return CalibrationView(
        calibration_id=run.run_id,
        status=run.status,
        progress=run.progress,
        message=run.message,
        num_poses=run.num_poses,
        started_at=as_utc(run.started_at),
        reprojection_error=run.outcome.reprojection_error if run.outcome else None,
        parameters=run.outcome.parameters if run.outcome else None,
    )


@router.api_route(
    "/handshake",
    methods=["GET", "HEAD", "PUT", "PATCH", "DELETE", "OPTIONS", "TRACE"],
    include_in_schema=False,
)
async def handshake_other_methods() -> None:
    """Without this, ``GET /calibration/handshake`` would reach ``/{calibration_id}`` and answer 422."""
    raise HTTPException(405, "Method Not Allowed")


@router.get("/{calibration_id}", response_model=CalibrationView, responses={**READ_DB, **errors(404)})
async def get_calibration(
    cell: CellDep, calibration_id: Annotated[str, Path(pattern=r"^[0-9a-f]{1,32}$")]
) -> CalibrationView:
    run = await cell.calibration.get(calibration_id)
    if run is None:
        raise HTTPException(404, f"calibration {calibration_id} not found")
    return _view(run)
