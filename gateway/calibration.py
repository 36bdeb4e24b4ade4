"""Hand-eye calibration runs started over REST (``POST /calibration/handshake``).

The gateway does not calibrate: a :class:`CalibrationExecutor` does (the vision service's
routine that moves the arm through poses and solves AX = XB). The gateway starts one run at a
time, tracks its progress for ``GET /calibration/{id}``, and records it in ``calibrations``.
"""

from __future__ import annotations

import asyncio
import logging
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, Protocol

from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from gateway.db.models import Calibration
from gateway.db.repository import CalibrationRepository
from gateway.schemas import CalibrationStatus
from services.common.errors import ConfigurationError, ExecutionError, RobotError

log = logging.getLogger("pickplace.gateway.calibration")

Progress = Callable[[float, str], None]  # (fraction done, message)


@dataclass(frozen=True)
class CalibrationOutcome:
    parameters: dict[str, Any]  # e.g. {"T_base_camera": [[...]], "poses_used": 14}
    reprojection_error: float | None
    notes: str = ""


class CalibrationExecutor(Protocol):
    async def __call__(self, num_poses: int, progress: Progress) -> CalibrationOutcome: ...


@dataclass
class CalibrationRun:
    run_id: str
    num_poses: int
    started_at: datetime
    status: CalibrationStatus = CalibrationStatus.RUNNING
    progress: float = 0.0
    message: str = "starting"
    outcome: CalibrationOutcome | None = None
    task: asyncio.Task[None] | None = field(default=None, repr=False)


class CalibrationRuns:
    def __init__(
        self,
        executor: CalibrationExecutor | None,
        sessions: async_sessionmaker[AsyncSession],
        robot_id: str,
    ):
        self.executor = executor
        self.sessions = sessions
        self.robot_id = robot_id
        self.runs: dict[str, CalibrationRun] = {}

    def active(self) -> CalibrationRun | None:
        return next((r for r in self.runs.values() if r.status is CalibrationStatus.RUNNING), None)

    async def start(self, num_poses: int) -> CalibrationRun:
        if self.executor is None:
            raise ConfigurationError(
                "no hand-eye calibration routine is connected to this gateway: `pickplace up` provides one; "
                "elsewhere run `pickplace calibrate` against the cell"
            )
        running = self.active()
        if running is not None:
            raise ExecutionError(f"calibration {running.run_id} is still running ({running.progress:.0%})")
        run = CalibrationRun(uuid.uuid4().hex[:12], num_poses, datetime.now(UTC))
        async with self.sessions() as s:
            s.add(
                Calibration(
                    run_id=run.run_id,
                    timestamp=run.started_at,
                    robot_id=self.robot_id,
                    calibration_type="hand_eye",
                    status=run.status.value,
                    num_poses=num_poses,
                )
            )
            await s.commit()
        self.runs[run.run_id] = run
        run.task = asyncio.create_task(self._run(run), name=f"gateway-calibration-{run.run_id}")
        return run

    async def _run(self, run: CalibrationRun) -> None:
        assert self.executor is not None

        def progress(fraction: float, message: str) -> None:
            run.progress = min(max(float(fraction), 0.0), 1.0)
            run.message = message

        try:
            run.outcome = await self.executor(run.num_poses, progress)
            run.status, run.progress, run.message = (
                CalibrationStatus.SUCCEEDED,
                1.0,
                run.outcome.notes or "done",
            )
        except asyncio.CancelledError:
            run.status, run.message = CalibrationStatus.FAILED, "cancelled (gateway shutting down)"
            raise
        except RobotError as exc:
            run.status, run.message = CalibrationStatus.FAILED, f"{type(exc).__name__}: {exc}"
        except Exception as exc:
            log.exception("calibration %s crashed", run.run_id)
            run.status, run.message = CalibrationStatus.FAILED, f"{type(exc).__name__}: {exc}"
        finally:
            await self._record(run)

    async def _record(self, run: CalibrationRun) -> None:
        try:
            async with self.sessions() as s:
                row = await CalibrationRepository(s).by_run_id(run.run_id)
                if row is not None:
                    row.status = run.status.value
                    row.notes = run.message
                    if run.outcome is not None:
                        row.parameters = run.outcome.parameters
                        row.reprojection_error = run.outcome.reprojection_error
                    await s.commit()
        except Exception as exc:  # the result stays visible in memory
            log.error("could not record calibration %s: %s", run.run_id, exc)

    async def get(self, run_id: str) -> CalibrationRun | None:
        if run_id in self.runs:
            return self.runs[run_id]
        async with self.sessions() as s:
            row = await CalibrationRepository(s).by_run_id(run_id)
        if row is None:
            return None
        recorded = CalibrationStatus(row.status)
        outcome = None
        if row.parameters is not None:
            outcome = CalibrationOutcome(row.parameters, row.reprojection_error, row.notes or "")
        return CalibrationRun(
            run_id=row.run_id,
            num_poses=row.num_poses or 0,
            started_at=row.timestamp,
            # a run still "running" in the database is one the previous process lost
            status=CalibrationStatus.FAILED if recorded is CalibrationStatus.RUNNING else recorded,
            progress=1.0 if recorded is CalibrationStatus.SUCCEEDED else 0.0,
            message=row.notes
            or ("interrupted: the gateway restarted" if recorded is CalibrationStatus.RUNNING else ""),
            outcome=outcome,
        )

    async def close(self) -> None:
        for run in self.runs.values():
            if run.task is not None and not run.task.done():
                run.task.cancel()
        await asyncio.gather(*(r.task for r in self.runs.values() if r.task), return_exceptions=True)
