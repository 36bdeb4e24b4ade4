"""/calibration: start a hand-eye calibration run, follow its progress (LLD §13.1)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, HTTPException, Path

from gateway.calibration import CalibrationRun
from gateway.convert import as_utc
from gateway.deps import Authorized, CellDep
from gateway.schemas import CalibrationRequest, CalibrationStarted, CalibrationView

router = APIRouter(prefix="/calibration", tags=["calibration"])


@router.post("/handshake", response_model=CalibrationStarted, status_code=202, dependencies=Authorized)
async def start_calibration(
    cell: CellDep, body: CalibrationRequest | None = Body(None)
) -> CalibrationStarted:
    """Start a hand-eye calibration run; poll ``GET /calibration/{id}`` for progress and result."""
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


@router.get("/{calibration_id}", response_model=CalibrationView)
async def get_calibration(
    cell: CellDep, calibration_id: Annotated[str, Path(pattern=r"^[0-9a-f]{1,32}$")]
) -> CalibrationView:
    run = await cell.calibration.get(calibration_id)
    if run is None:
        raise HTTPException(404, f"calibration {calibration_id} not found")
    return _view(run)
