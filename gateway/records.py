"""Pick rows and events as the REST/WebSocket JSON the dashboard shows."""

from __future__ import annotations

from typing import Any

from pickplace.v1 import task_pb2

from gateway.convert import as_utc, pick_row
from gateway.db.models import Pick
from gateway.schemas import PickDetail, PickRecord

RECORD_FIELDS = tuple(PickRecord.model_fields)


def with_utc(row: dict[str, Any]) -> dict[str, Any]:
    row["timestamp"] = as_utc(row["timestamp"])
    return row


def pick_detail(row: Pick) -> PickDetail:
    rec = PickDetail.model_validate(row)
    rec.timestamp = as_utc(rec.timestamp)
    return rec


def pick_json(db_id: int, ev: task_pb2.PickEvent, default_robot_id: str) -> dict[str, Any]:
    row = pick_row(ev, default_robot_id)
    fields = set(PickRecord.model_fields)
    return PickRecord.model_validate(
        {"id": db_id, **{k: v for k, v in row.items() if k in fields}}
    ).model_dump(mode="json")
