"""PUT /config: which settings may change while the cell runs, and their validation.

A patch is a partial settings document (``{"robot": {"speed_ratio": 30}}``). Every leaf must lie
under one of :data:`UPDATABLE`; each touched section is re-validated as a whole by its settings
model, so the same rules that guard start-up (speed ratio 1–100 %, an ordered workspace box…)
guard a live change. Nothing is applied unless everything is valid.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ValidationError

from services.common.errors import InvalidInputError
from services.common.settings import Settings, deep_merge

UPDATABLE: tuple[str, ...] = (
    "robot.speed_ratio",
    "robot.acc_ratio",
    "robot.workspace",
    "motion.planner",
    "motion.planning_time_s",
    "motion.velocity_scale",
    "motion.acceleration_scale",
    "vision.rate_hz",
    "vision.detect_rods",
    "vision.detect_cubes",
    "sim.twin.scene.drop_zones_m",
    "sim.twin.scene.rod_place_m",
    "cycle.move_duration_s",
    "cycle.dwell_s",
    "gateway.joint_state_rate_hz",
)


# The changes the gateway puts into effect itself; every other service reads its settings at start.
LIVE: frozenset[str] = frozenset({"gateway.joint_state_rate_hz"})


class ConfigRejected(InvalidInputError):
    """Carries one entry per offending field: ``[{"field": "robot.speed_ratio", "message": …}]``."""

    def __init__(self, errors: list[dict[str, str]]):
        self.errors = errors
        super().__init__("; ".join(f"{e['field']}: {e['message']}" for e in errors))


def leaf_paths(patch: dict[str, Any], prefix: str = "") -> list[str]:
    out: list[str] = []
    for key, value in patch.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict) and value and not _is_updatable_leaf_dict(path):
            out += leaf_paths(value, path + ".")
        else:
            out.append(path)
    return out


def _is_updatable_leaf_dict(path: str) -> bool:
    # a dict-valued setting (drop_zones_m) is replaced whole, not merged key by key
    return path in ("sim.twin.scene.drop_zones_m",)


def is_updatable(path: str) -> bool:
    return any(path == u or path.startswith(u + ".") for u in UPDATABLE)


def apply_patch(current: Settings, patch: Any) -> tuple[Settings, list[str]]:
    """The settings with ``patch`` applied, and the leaf paths it changed; ConfigRejected if anything is off."""
    if not isinstance(patch, dict) or not patch:
        raise ConfigRejected([{"field": "body", "message": "expected a non-empty JSON object of settings"}])
    paths = leaf_paths(patch)
    refused = [p for p in paths if not is_updatable(p)]
    if refused:
        raise ConfigRejected(
            [{"field": p, "message": f"cannot be changed at runtime (changeable: {', '.join(UPDATABLE)})"}
             for p in refused]
        )
    errors: list[dict[str, str]] = []
    updates: dict[str, BaseModel] = {}
    for section, section_patch in patch.items():
        model: BaseModel = getattr(current, section)
        merged = _replace_leaf_dicts(deep_merge(model.model_dump(), section_patch), section_patch, section)
        try:
            updates[section] = type(model).model_validate(merged)
        except ValidationError as exc:
            for e in exc.errors():
                loc = ".".join(str(p) for p in (section, *e["loc"]))
                errors.append({"field": loc, "message": e["msg"]})
    if errors:
        raise ConfigRejected(errors)
    new = current.model_copy(update=updates)
    changed = [p for p in paths if _get(new, p) != _get(current, p)]
    return new, changed


def _replace_leaf_dicts(merged: dict[str, Any], section_patch: dict[str, Any], prefix: str) -> dict[str, Any]:
    for key, value in section_patch.items():
        path = f"{prefix}.{key}"
        if isinstance(value, dict):
            if _is_updatable_leaf_dict(path):
                merged[key] = value
            elif isinstance(merged.get(key), dict):
                merged[key] = _replace_leaf_dicts(merged[key], value, path)
    return merged


def _get(obj: Any, path: str) -> Any:
    for part in path.split("."):
        obj = obj.get(part) if isinstance(obj, dict) else getattr(obj, part, None)
    return obj
