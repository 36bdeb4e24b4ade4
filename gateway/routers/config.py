"""/config: read the running configuration; change the parts that may change at runtime (LLD §13.1).

The gateway applies its own settings at once; the other services read theirs when they start, and
the answer to PUT says which of the changed fields wait for that."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body

from gateway.config_update import LIVE, UPDATABLE, apply_patch
from gateway.deps import Authorized, CellDep
from gateway.schemas import ConfigUpdateResult

router = APIRouter(prefix="/config", tags=["config"])


@router.get("")
async def get_config(cell: CellDep) -> dict[str, Any]:
    """The validated settings in force (secrets masked, database password hidden) and what PUT may change."""
    doc = cell.settings.model_dump(mode="json")
    doc["database"]["url"] = cell.database_display
    doc["gateway"]["api_token"] = "**********"
    doc["updatable"] = list(UPDATABLE)
    return doc


@router.put("", response_model=ConfigUpdateResult, dependencies=Authorized)
async def put_config(cell: CellDep, patch: Any = Body(..., examples=[{"robot": {"speed_ratio": 30}}])) -> ConfigUpdateResult:
    """Apply a partial settings document. 422 names every refused field; nothing changes then."""
    new, changed = apply_patch(cell.settings, patch)
    cell.settings = new
    if "gateway.joint_state_rate_hz" in changed:
        cell.hub.set_joint_rate(new.gateway.joint_state_rate_hz)
    cell.hub.on_event("config", {"updated": changed})
    now = [c for c in changed if c in LIVE]
    return ConfigUpdateResult(success=True, updated=changed, applied_now=now,
                              applied_at_restart=[c for c in changed if c not in LIVE])
