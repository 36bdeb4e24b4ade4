"""/metrics under /api/v1: the LLD's JSON summary (Prometheus text is at the root /metrics)."""

from __future__ import annotations

from datetime import UTC, datetime

from fastapi import APIRouter

from gateway.contract import READ_DB
from gateway.deps import CellDep, PicksDep
from gateway.schemas import MetricsSummary

router = APIRouter(tags=["metrics"])


@router.get("/metrics", response_model=MetricsSummary, responses=READ_DB)
async def summary(cell: CellDep, repo: PicksDep) -> MetricsSummary:
    s = await cell.cache.get(("summary",), lambda: repo.summary(datetime.now(UTC)))
    return MetricsSummary(
        success_rate=s.success_rate,
        avg_cycle_time=s.avg_cycle_time_s,
        uptime=round(cell.uptime_s, 3),
        picks_total=s.total,
        picks_succeeded=s.succeeded,
        picks_failed=s.failed,
        picks_today=s.picks_today,
        cycle_time_p50=s.p50_cycle_time_s,
        cycle_time_p95=s.p95_cycle_time_s,
    )
