"""/metrics at the root: Prometheus text exposition of the gateway's registry."""

from __future__ import annotations

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST

from gateway.deps import CellDep
from services.common.metrics import render

router = APIRouter(tags=["prometheus"])


@router.get(
    "/metrics",
    response_class=Response,
    responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}}, "description": "exposition"}},
)
async def prometheus_metrics(cell: CellDep) -> Response:
    cell.metrics.pick_buffer_depth.set(len(cell.writer.buffer))
    return Response(render(cell.metrics.registry, cell.metrics_export), media_type=CONTENT_TYPE_LATEST)
