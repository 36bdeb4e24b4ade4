"""/config: read the running configuration; change the parts that may change at runtime (LLD §13.1).

An accepted change is published to the services over Zenoh (pickplace/<cell>/config/updates); each
applies it to its own settings at once, or at its next cycle for the demo cycle and the twin's scene.
Changes last until the cell restarts."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body

from gateway.contract import MUTATE, config_patch_model, patch_document
from gateway.deps import Authorized, CellDep
from gateway.schemas import ConfigUpdateResult
from services.common.config_patch import UPDATABLE, apply_patch, merge_patches, when_applied

router = APIRouter(prefix="/config", tags=["config"])

ConfigPatch = config_patch_model()


@router.get("")
async def get_config(cell: CellDep) -> dict[str, Any]:
    """The validated settings in force (secrets masked, database password hidden) and what PUT may change."""
    doc = cell.settings.model_dump(mode="json")
    doc["database"]["url"] = cell.database_display
    doc["gateway"]["api_token"] = "**********"
    doc["updatable"] = list(UPDATABLE)
    return doc


@router.put("", response_model=ConfigUpdateResult, dependencies=Authorized, responses=MUTATE)
async def put_config(
    cell: CellDep,
    body: ConfigPatch = Body(..., examples=[{"robot": {"speed_ratio": 30}}]),  # type: ignore[valid-type]
) -> ConfigUpdateResult:
    """Apply a partial settings document. 422 names every refused field; nothing changes then.

    Each section is validated as a whole (a workspace whose min is not below its max, a drop zone
    for every cube colour), so a document the schema allows can still be refused with 422."""
    patch = patch_document(body)
    new, changed = apply_patch(cell.settings, patch)
    cell.settings = new
    if changed:
        cell.config_patch = merge_patches(cell.config_patch, patch)
        cell.publish_config(changed)
    if "gateway.joint_state_rate_hz" in changed:
        cell.hub.set_joint_rate(new.gateway.joint_state_rate_hz)
    cell.hub.on_event("config", {"updated": changed})
    return ConfigUpdateResult(
        success=True,
        updated=changed,
        applied_now=[c for c in changed if when_applied(c) == "now"],
        applied_next_cycle=[c for c in changed if when_applied(c) == "next_cycle"],
    )
