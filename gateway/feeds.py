"""Zenoh → gateway: task status, joint states, robot status, pick events (outcomes and the running
records of cycles in progress), the vision debug image.

Zenoh calls back on its own threads; each sample is decoded there and handed to the event loop
with ``call_soon_threadsafe``. Pick events are never dropped on the way (they go to the
writer's buffer); state streams are only ever "newest wins".
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from typing import Any

from google.protobuf.message import DecodeError, Message
from pickplace.v1 import common_pb2, robot_pb2, task_pb2, vision_pb2

from services.common.bus import Bus
from services.common.keys import CellKeys

log = logging.getLogger("pickplace.gateway.feeds")

JPEG_MAGIC = b"\xff\xd8"


class BusFeeds:
    def __init__(
        self,
        bus: Bus,
        keys: CellKeys,
        *,
        on_task_status: Callable[[task_pb2.TaskStatus], None],
        on_joint_state: Callable[[common_pb2.JointState], None],
        on_robot_status: Callable[[robot_pb2.RobotStatus], None],
        on_pick_event: Callable[[task_pb2.PickEvent], None],
        on_camera: Callable[[bytes], None],
        on_detections: Callable[[vision_pb2.DetectedObjects], None] | None = None,
        on_frame: Callable[[bytes], None] | None = None,
        on_plan: Callable[[task_pb2.TaskPlan], None] | None = None,
    ):
        self._bus = bus
        self._keys = keys
        self._loop = asyncio.get_running_loop()
        self._subs: list[Any] = []
        self.decode_errors = 0
        self._routes: list[tuple[str, type[Message] | None, Callable[[Any], None]]] = [
            (keys.task_status, task_pb2.TaskStatus, on_task_status),
            (keys.joint_states, common_pb2.JointState, on_joint_state),
            (keys.robot_status, robot_pb2.RobotStatus, on_robot_status),
            (keys.pick_events, task_pb2.PickEvent, on_pick_event),
            (keys.pick_progress, task_pb2.PickEvent, on_pick_event),  # running records, same writer
            (keys.vision_debug_image, vision_pb2.DebugImage, self._camera_handler(on_camera)),
        ]
        if on_detections is not None:
            self._routes.append((keys.detected_objects, vision_pb2.DetectedObjects, on_detections))
        if on_plan is not None:
            self._routes.append((keys.task_plans, task_pb2.TaskPlan, on_plan))
        # camera frames stay serialised: kept as they come (on the Zenoh thread: one reference
        # assignment), decoded only when the dashboard asks for the colour or depth view
        self._on_frame = on_frame

    def _camera_handler(self, on_camera: Callable[[bytes], None]) -> Callable[[vision_pb2.DebugImage], None]:
        def handle(msg: vision_pb2.DebugImage) -> None:
            if msg.jpeg.startswith(JPEG_MAGIC):
                on_camera(msg.jpeg)
            else:
                self.decode_errors += 1

        return handle

    def start(self) -> None:
        for key, msg_type, handler in self._routes:
            self._subs.append(self._bus.subscribe_callback(key, self._callback(msg_type, handler)))
        if self._on_frame is not None:
            on_frame = self._on_frame
            self._subs.append(
                self._bus.subscribe_callback(self._keys.camera_frames, lambda _k, p: on_frame(p))
            )

    def _callback(
        self, msg_type: type[Message] | None, handler: Callable[[Any], None]
    ) -> Callable[[str, bytes], None]:
        def on_sample(key: str, payload: bytes) -> None:  # on a Zenoh thread
            if msg_type is None:
                if not payload.startswith(JPEG_MAGIC):
                    self.decode_errors += 1
                    return
                value: Any = payload
            else:
                try:
                    value = msg_type.FromString(payload)
                except DecodeError:
                    self.decode_errors += 1
                    log.warning("undecodable %s on %s (%d bytes)", msg_type.__name__, key, len(payload))
                    return
            with contextlib.suppress(RuntimeError):  # loop closed during shutdown
                self._loop.call_soon_threadsafe(handler, value)

        return on_sample

    def close(self) -> None:
        for sub in self._subs:
            with contextlib.suppress(Exception):
                sub.undeclare()
        self._subs.clear()
