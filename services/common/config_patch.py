"""PUT /config: which settings may change while the cell runs, and their validation.

A patch is a partial settings document (``{"robot": {"speed_ratio": 30}}``). Every leaf must lie
under one of :data:`UPDATABLE`; each touched section is re-validated as a whole by its settings
model, so the same rules that guard start-up (speed ratio 1–100 %, an ordered workspace box…)
guard a live change. Nothing is applied unless everything is valid. The gateway validates a PUT
with it; each service applies the published patch to its own settings with it again.
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


# When each change takes effect: at once (the gateway itself; the robot driver, motion and vision
# services on receiving the update), or at the next cycle / scene (the key-pose demo cycle, the
# twin's scene). Nothing waits for a restart; nothing survives one either (put it in a config file).
NEXT_CYCLE: frozenset[str] = frozenset(
    {
        "sim.twin.scene.drop_zones_m",
        "sim.twin.scene.rod_place_m",
        "cycle.move_duration_s",
        "cycle.dwell_s",
    }
)


def _under(path: str, roots: frozenset[str] | tuple[str, ...]) -> bool:
    """``path`` is one of ``roots`` or lies below one of them."""
    return any(path == r or path.startswith(r + ".") for r in roots)


def when_applied(path: str) -> str:
    """ "now" or "next_cycle" for an updatable leaf path."""
    return "next_cycle" if _under(path, NEXT_CYCLE) else "now"


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
    return _under(path, UPDATABLE)


def apply_patch(current: Settings, patch: Any) -> tuple[Settings, list[str]]:
    """The settings with ``patch`` applied, and the leaf paths it changed; ConfigRejected if anything is off."""
    if not isinstance(patch, dict) or not patch:
        raise ConfigRejected([{"field": "body", "message": "expected a non-empty JSON object of settings"}])
    paths = leaf_paths(patch)
    refused = [p for p in paths if not is_updatable(p)]
    if refused:
        raise ConfigRejected(
            [
                {"field": p, "message": f"cannot be changed at runtime (changeable: {', '.join(UPDATABLE)})"}
                for p in refused
            ]
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


def merge_patches(earlier: dict[str, Any], later: dict[str, Any]) -> dict[str, Any]:
    """One patch with the effect of ``earlier`` then ``later`` (the gateway keeps every accepted change)."""
    out = dict(earlier)
    for section, section_patch in later.items():
        if isinstance(section_patch, dict) and isinstance(out.get(section), dict):
            out[section] = _replace_leaf_dicts(
                deep_merge(out[section], section_patch), section_patch, section
            )
        else:
            out[section] = section_patch
    return out


def changed_paths(before: Settings, after: Settings, paths: list[str]) -> list[str]:
    """Those of ``paths`` whose value differs between two settings."""
    return [p for p in dict.fromkeys(paths) if _get(after, p) != _get(before, p)]
