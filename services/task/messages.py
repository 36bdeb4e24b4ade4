"""PickOutcome ↔ pickplace.v1.PickEvent (pure)."""

from __future__ import annotations

import time

from pickplace.v1 import common_pb2, task_pb2

from services.task.states import PickOutcome


def _pose(values: list[float] | None) -> common_pb2.Pose | None:
    if not values:
        return None
    x, y, z, qx, qy, qz, qw = values
    return common_pb2.Pose(x=x, y=y, z=z, qx=qx, qy=qy, qz=qz, qw=qw)


def pick_event_msg(
    o: PickOutcome, robot_id: str, status: task_pb2.PickStatus | None = None
) -> task_pb2.PickEvent:
    """The pick's record; ``status`` defaults to the outcome (succeeded or failed)."""
    if status is None:
        status = task_pb2.PICK_STATUS_SUCCEEDED if o.success else task_pb2.PICK_STATUS_FAILED
    msg = task_pb2.PickEvent(
        header=common_pb2.Header(stamp_ns=time.time_ns(), frame_id="base"),
        pick_id=o.pick_id,
        robot_id=robot_id,
        object_id=o.object_id,
        object_class=o.object_class,
        grasp_quality=o.grasp_quality,
        cycle_time_s=o.cycle_time_s,
        success=o.success,
        stage_reached=o.stage_reached,
        failure_reason=o.failure_reason,
        error_code=o.error_code,
        attempts=o.attempts,
        task=o.task,
        status=status,
    )
    for key, value in o.stage_durations_s.items():
        msg.stage_durations_s[key] = value
    pick, place = _pose(o.pick_pose), _pose(o.place_pose)
    if pick is not None:
        msg.pick_pose.CopyFrom(pick)
    if place is not None:
        msg.place_pose.CopyFrom(place)
    return msg
