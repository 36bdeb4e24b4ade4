"""Pure conversions at the gateway's edge: protobuf pick events → database rows → REST records."""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Any

from google.protobuf.json_format import MessageToDict
from pickplace.v1 import common_pb2, task_pb2

from gateway.db.models import PickState
from services.common.errors import InvalidInputError

PICK_ID_MAX = 64


def _clip(text: str, n: int) -> str | None:
    if not text:
        return None
    return text if len(text) <= n else text[: n - 1] + "…"


def pose_dict(pose: common_pb2.Pose, what: str) -> dict[str, float] | None:
    values = {k: float(getattr(pose, k)) for k in ("x", "y", "z", "qx", "qy", "qz", "qw")}
    if all(v == 0.0 for v in values.values()):
        return None  # an unset pose (no quaternion can be all zeros)
    bad = [k for k, v in values.items() if not math.isfinite(v)]
    if bad:
        raise InvalidInputError(f"{what} has non-finite {bad}: {values}")
    return values


def stamp_datetime(stamp_ns: int) -> datetime:
    return datetime.fromtimestamp(stamp_ns / 1e9, UTC) if stamp_ns > 0 else datetime.now(UTC)


def validate_pick_event(ev: task_pb2.PickEvent) -> None:
    """Raise InvalidInputError naming what is wrong; a valid event can always be stored."""
    if not ev.pick_id:
        raise InvalidInputError("pick event has an empty pick_id (the idempotency key)")
    if len(ev.pick_id) > PICK_ID_MAX:
        raise InvalidInputError(f"pick_id longer than {PICK_ID_MAX} characters: {ev.pick_id[:80]!r}")
    for name in ("grasp_quality", "cycle_time_s"):
        v = getattr(ev, name)
        if not math.isfinite(v) or v < 0:
            raise InvalidInputError(f"pick {ev.pick_id}: {name} must be finite and >= 0, got {v}")
    for stage, seconds in ev.stage_durations_s.items():
        if not math.isfinite(seconds):
            raise InvalidInputError(f"pick {ev.pick_id}: stage duration of {stage!r} is {seconds}")
    pose_dict(ev.pick_pose, "pick_pose")
    pose_dict(ev.place_pose, "place_pose")
    if ev.status != task_pb2.PICK_STATUS_UNSPECIFIED and ev.status not in _PICK_STATES:
        raise InvalidInputError(f"pick {ev.pick_id}: unknown status {ev.status}")


_PICK_STATES = {
    task_pb2.PICK_STATUS_RUNNING: PickState.RUNNING,
    task_pb2.PICK_STATUS_SUCCEEDED: PickState.SUCCEEDED,
    task_pb2.PICK_STATUS_FAILED: PickState.FAILED,
    task_pb2.PICK_STATUS_INTERRUPTED: PickState.INTERRUPTED,
}


def pick_state(ev: task_pb2.PickEvent) -> PickState:
    """Where the event puts its pick's record (a sender without ``status``: ``success`` says)."""
    state = _PICK_STATES.get(ev.status)
    if state is not None:
        return state
    return PickState.SUCCEEDED if ev.success else PickState.FAILED


def pick_row(ev: task_pb2.PickEvent, default_robot_id: str) -> dict[str, Any]:
    """The ``picks`` row of a validated event (strings clipped to their column widths)."""
    validate_pick_event(ev)
    return {
        "pick_id": ev.pick_id,
        "timestamp": stamp_datetime(ev.header.stamp_ns),
        "robot_id": _clip(ev.robot_id, 50) or default_robot_id,
        "object_id": _clip(ev.object_id, 100),
        "object_class": _clip(ev.object_class, 50),
        "pick_pose": pose_dict(ev.pick_pose, "pick_pose"),
        "place_pose": pose_dict(ev.place_pose, "place_pose"),
        "grasp_quality": float(ev.grasp_quality) if ev.grasp_quality else None,
        "cycle_time": float(ev.cycle_time_s) if ev.cycle_time_s else None,
        "success": bool(ev.success),
        "error_code": _clip(ev.error_code, 100),
        "error_message": ev.failure_reason or None,
        "task": _clip(ev.task, 32),
        "stage_reached": _clip(ev.stage_reached, 32),
        "stage_durations": dict(ev.stage_durations_s) or None,
        "attempts": int(ev.attempts) if ev.attempts else None,
        "outcome": pick_state(ev).value,
    }


def as_utc(ts: datetime) -> datetime:
    """SQLite hands timestamps back naive; they were written as UTC."""
    return ts if ts.tzinfo is not None else ts.replace(tzinfo=UTC)


def message_dict(msg: Any) -> dict[str, Any]:
    """A protobuf message as a JSON-ready dict with its field names, defaults included."""
    return MessageToDict(msg, preserving_proto_field_name=True, always_print_fields_with_no_presence=True)
