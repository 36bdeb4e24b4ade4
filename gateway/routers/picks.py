"""/picks: the pick history with paging (LLD §13.1)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, Query, Response

from gateway.contract import LARGEST_ID, READ_DB, errors, pick_links
from gateway.deps import CellDep, PicksDep
from gateway.records import RECORD_FIELDS, pick_detail, with_utc
from gateway.schemas import PickDetail, PickRecord

router = APIRouter(prefix="/picks", tags=["picks"])


@router.get(
    "",
    response_model=list[PickRecord],
    responses={
        **READ_DB,
        200: {
            "links": pick_links(),
            "headers": {"X-Total-Count": {"description": "matching picks", "schema": {"type": "integer"}}},
        },
    },
)
async def list_picks(
    repo: PicksDep,
    cell: CellDep,
    response: Response,
    limit: Annotated[int, Query(ge=1, le=1000, description="page size")] = 100,
    offset: Annotated[int, Query(ge=0, le=10_000_000)] = 0,
    success: Annotated[
        bool | None, Query(description="only successful (true) or failed (false) picks")
    ] = None,
    robot_id: Annotated[str | None, Query(max_length=50)] = None,
) -> list[dict[str, Any]]:
    """Newest first. The total number of matching picks is in the ``X-Total-Count`` header."""
    rows = await repo.page_rows(RECORD_FIELDS, limit, offset, success, robot_id)
    total = await cell.cache.get(("count", success, robot_id), lambda: repo.count(success, robot_id))
    response.headers["X-Total-Count"] = str(total)
    return [with_utc(r) for r in rows]  # rows, not models: validated once, by the response model


@router.get("/{pick_id}", response_model=PickDetail, responses={**READ_DB, **errors(404)})
async def get_pick(
    repo: PicksDep, pick_id: Annotated[int, Path(ge=1, le=LARGEST_ID, description="the pick's row id")]
) -> PickDetail:
    row = await repo.get(pick_id)
    if row is None:
        raise HTTPException(404, f"pick {pick_id} not found")
    return pick_detail(row)
