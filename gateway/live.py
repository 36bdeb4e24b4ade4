"""The latest cell state, and its fan-out to browser connections.

Everything runs on the event loop (the Zenoh adapter hands samples over thread-safely).
Each connection has a bounded queue; a slow browser loses old state messages (the newest
matters), never blocks the others. A message is serialised once, whatever the number of
connections. Joint states are decimated to ``joint_rate_hz`` here.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections import deque
from collections.abc import Callable, Iterator
from typing import Any

from pickplace.v1 import common_pb2, robot_pb2, task_pb2, vision_pb2

from gateway.camera import detections_json
from gateway.convert import message_dict
from services.common.sensors import RGBDFrame

CLIENT_QUEUE = 64
TIMELINE_KEPT = 200  # the alarms-and-events timeline a dashboard gets when it connects
TIMELINE_KINDS = frozenset({"task_status", "robot_status", "picks", "estop", "estop_task", "config"})
PLANS_KEPT = 12  # plans of one cycle the dashboard draws (a cycle has a few; re-plans add more)

Message = dict[str, Any]


def encode(message: Message) -> str:
    """The WebSocket text of one message."""
    return json.dumps(message, separators=(",", ":"))


def joint_state_json(msg: common_pb2.JointState) -> Message:
    p = msg.tcp_pose
    return {
        "stamp_ns": msg.header.stamp_ns,
        "source_stamp_ns": msg.source_stamp_ns,
        "seq": msg.header.seq,
        "name": list(msg.name),
        "position": [round(q, 6) for q in msg.position],
        "velocity": [round(v, 5) for v in msg.velocity],
        "robot_mode": msg.robot_mode,
        "tcp": [round(v, 5) for v in (p.x, p.y, p.z, p.qx, p.qy, p.qz, p.qw)],
        "force": [round(f, 3) for f in msg.tcp_force],
        "digital_outputs": msg.digital_outputs,
    }


def robot_status_json(st: robot_pb2.RobotStatus) -> Message:
    return {
        "robot_mode": st.robot_mode,
        "robot_mode_name": st.robot_mode_name,
        "enabled": st.enabled,
        "connected": st.connected,
        "alarms": list(st.alarms),
        "gripper_closed": st.gripper_closed,
        "estop_active": st.estop_active,
        "robot_model": st.robot_model,
    }


class LiveHub:
    def __init__(self, joint_rate_hz: float = 20.0):
        self._min_joint_interval_ns = int(1e9 / joint_rate_hz)
        self._next_joint_ns = 0
        self._queues: set[asyncio.Queue[str]] = set()
        self.task_status: Message | None = None
        self.joint_state: Message | None = None
        self.robot_status: Message | None = None
        self.robot_status_at: float = 0.0
        self.camera_jpeg: bytes | None = None
        self.camera_seq = 0
        self.detections: Message | None = None
        self.plan: Message | None = None  # the current cycle's plans (tool paths)
        # what the dashboard's timeline is made of, with the wall time it happened (ms since the epoch):
        # robot status changes, task state changes, failed picks, e-stops, settings changes
        self.timeline: deque[Message] = deque(maxlen=TIMELINE_KEPT)
        self._timeline_task_state: str | None = None
        self.frame_payload: bytes | None = None  # the camera's newest RGBDFrame, serialised (bus)
        self.frame_object: RGBDFrame | None = None  # or as the in-process camera gave it (embedded cell)
        self.frame_count = 0
        self.view_cache: tuple[tuple[str, int], bytes] | None = None  # ((view, frame_count), jpeg)
        self.sent = 0
        self.on_change: Callable[[str], None] | None = None  # every non-joint message (the status snapshot)

    def set_joint_rate(self, rate_hz: float) -> None:
        self._min_joint_interval_ns = int(1e9 / rate_hz)

    # ----------------------------------------------------------------- inputs
    def on_task_status(self, msg: task_pb2.TaskStatus) -> None:
        self.task_status = message_dict(msg)
        self._broadcast({"type": "task_status", "data": self.task_status})

    def on_joint_state(self, msg: common_pb2.JointState) -> bool:
        """Keep and forward at most ``joint_rate_hz`` states per second; True when forwarded."""
        # on the controller's clock (its feedback TimeStamp) when the state carries it: the driver's
        # receive stamps bunch up when the machine is busy, the controller's do not
        stamp = msg.source_stamp_ns or msg.header.stamp_ns or time.time_ns()
        if stamp < self._next_joint_ns:
            return False
        # Keep a fixed schedule, so 125 Hz in gives the full rate out (a minimum gap would give 17.9 Hz);
        # after a pause in the stream, start the schedule again from this sample.
        on_schedule = stamp - self._next_joint_ns < self._min_joint_interval_ns
        self._next_joint_ns = (self._next_joint_ns if on_schedule else stamp) + self._min_joint_interval_ns
        self.joint_state = joint_state_json(msg)
        self._broadcast({"type": "joint_state", "data": self.joint_state})
        return True

    def on_robot_status(
        self, st: robot_pb2.RobotStatus | None, error: str | None = None, asked_at: float | None = None
    ) -> None:
        """``asked_at`` (monotonic) is when the status was requested: an answer to an older request
        than the one already shown (a poll overtaken by the e-stop's refresh) is ignored."""
        asked = time.monotonic() if asked_at is None else asked_at
        if asked < self.robot_status_at:
            return
        data = robot_status_json(st) if st is not None else {"connected": False, "error": error}
        self.robot_status_at = asked
        if data != self.robot_status:
            self.robot_status = data
            self._broadcast({"type": "robot_status", "data": data})

    def on_picks(self, picks: list[Message]) -> None:
        self._broadcast({"type": "picks", "data": picks})

    def on_camera(self, jpeg: bytes) -> None:
        self.camera_jpeg = jpeg
        self.camera_seq += 1
        self._broadcast({"type": "camera", "data": {"seq": self.camera_seq, "bytes": len(jpeg)}})

    def on_detections(self, msg: vision_pb2.DetectedObjects) -> None:
        self.detections = detections_json(msg)
        self._broadcast({"type": "detections", "data": self.detections})

    def on_frame(self, payload: bytes) -> None:
        """Any thread (Zenoh's): one assignment; nothing decoded here."""
        self.frame_payload = payload
        self.frame_count += 1

    def on_sensor_frame(self, frame: RGBDFrame) -> None:
        """Any thread (the embedded cell's camera tap): one assignment; nothing encoded here."""
        self.frame_object = frame
        self.frame_count += 1

    def on_plan(self, msg: task_pb2.TaskPlan) -> None:
        """A plan the task got from motion: kept with the others of its cycle (a new cycle starts afresh),
        the newest ``PLANS_KEPT``; the dashboard draws them as the current cycle's planned path."""
        if self.plan is None or self.plan["cycle_index"] != msg.cycle_index:
            self.plan = {"cycle_index": msg.cycle_index, "source": "task plans", "plans": []}
        self.plan["plans"] = [
            *self.plan["plans"][-(PLANS_KEPT - 1) :],
            {
                "seq": msg.header.seq,
                "stamp_ns": msg.header.stamp_ns,
                "label": msg.label,
                "path": [[round(p.x, 4), round(p.y, 4), round(p.z, 4)] for p in msg.tool_path],
            },
        ]
        self._broadcast({"type": "plan", "data": self.plan})

    def on_event(self, kind: str, data: Message) -> None:
        """Anything else worth showing (e-stop pressed, config changed)."""
        self._broadcast({"type": kind, "data": data})

    # ----------------------------------------------------------------- outputs
    def snapshot(self) -> list[Message]:
        """What a new connection gets first: the timeline so far, then the current state."""
        out: list[Message] = [{"type": "timeline", "data": list(self.timeline)}]
        if self.task_status is not None:
            out.append({"type": "task_status", "data": self.task_status})
        if self.robot_status is not None:
            out.append({"type": "robot_status", "data": self.robot_status})
        if self.joint_state is not None:
            out.append({"type": "joint_state", "data": self.joint_state})
        if self.camera_jpeg is not None:
            out.append({"type": "camera", "data": {"seq": self.camera_seq, "bytes": len(self.camera_jpeg)}})
        if self.detections is not None:
            out.append({"type": "detections", "data": self.detections})
        if self.plan is not None:
            out.append({"type": "plan", "data": self.plan})
        return out

    @contextlib.contextmanager
    def connection(self) -> Iterator[asyncio.Queue[str]]:
        """A queue of the messages' texts: the current state first, then every change."""
        q: asyncio.Queue[str] = asyncio.Queue(CLIENT_QUEUE)
        for m in self.snapshot():
            q.put_nowait(encode(m))
        self._queues.add(q)
        try:
            yield q
        finally:
            self._queues.discard(q)

    @property
    def connections(self) -> int:
        return len(self._queues)

    def _remember(self, message: Message) -> None:
        kind = message["type"]
        if kind == "task_status":  # every 0.5 s: only a new state is news
            state = message["data"].get("state")
            if state == self._timeline_task_state:
                return
            self._timeline_task_state = state
        elif kind == "picks":
            failed = [p for p in message["data"] if not p.get("success")]
            if not failed:
                return
            message = {"type": kind, "data": failed}
        self.timeline.append({"at_ms": time.time_ns() // 1_000_000, **message})

    def _broadcast(self, message: Message) -> None:
        if message["type"] in TIMELINE_KINDS:
            self._remember(message)
        if self.on_change is not None and message["type"] not in ("joint_state", "detections", "plan"):
            self.on_change(message["type"])
        if not self._queues:
            return
        text = encode(message)
        for q in list(self._queues):
            if q.full():
                with contextlib.suppress(asyncio.QueueEmpty):
                    q.get_nowait()
            q.put_nowait(text)
            self.sent += 1
