"""The live view and the recorder: the cell's Zenoh streams into a Foxglove WebSocket server and MCAP files.

A thin shell around :mod:`~services.record.convert` (messages → Foxglove payloads) and
:mod:`~services.record.writer` (MCAP files). Sources:

- the bus: joint states, detections, task status, pick events, the task's plans (tool path and planning
  scene), robot status and camera frames (the frame stream of the multi-process cell,
  ``CellKeys.camera_frames``);
- :meth:`RecordService.offer_frame`: the frames vision detected on, handed over in-process by the
  composition root (``pickplace up``, where the twin camera is not on the bus), with the calibration
  vision used;
- an optional robot-status source (the driver's GetStatus: mode and alarms), polled;
- the Python logging of the process (``/log``).

Zenoh threads and the logging handler only enqueue; one converter thread owned by the shell does the
converting and logging to both sinks, so neither the bus nor the event loop waits on JPEG encoding or a
disk. The live view and the recording have separate foxglove contexts: a recording that fails (a full
disk) stops with an error event while the live view and the cell go on.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import enum
import logging
import queue
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import foxglove
import numpy as np
from foxglove.websocket import ChannelView, Client, ServerListener
from pickplace.v1 import common_pb2, robot_pb2, task_pb2, vision_pb2

from services.common.bus import Bus
from services.common.errors import ConfigurationError
from services.common.keys import CellKeys
from services.common.sensors import RGBDFrame, msg_to_frame
from services.common.settings import Settings
from services.common.shell import ServiceShell
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_geometry
from services.kinematics.urdf import robot_urdf
from services.record import convert, scene
from services.record.channels import Topic, open_channels
from services.record.writer import Opener, Recorder, RecordingStopped, open_new

log = logging.getLogger("pickplace.record.service")

URDF_ASSET_URI = "package://pickplace/robot.urdf"  # what the layout's URDF layer fetches from the server
MAX_QUEUED_FRAMES = 2  # frames are large: the converter takes the newest, older ones are dropped

RobotStatusSource = Callable[[], Awaitable[robot_pb2.RobotStatus]]


class Kind(enum.Enum):
    JOINTS = enum.auto()
    DETECTIONS = enum.auto()
    TASK_STATUS = enum.auto()
    PICK = enum.auto()
    ROBOT_STATUS = enum.auto()
    BUS_FRAME = enum.auto()
    FRAME = enum.auto()
    LOG = enum.auto()
    PLAN = enum.auto()
    RESEND = enum.auto()  # a client subscribed: send the description and calibration again
    STOP = enum.auto()


@dataclass(frozen=True)
class Item:
    kind: Kind
    received_ns: int
    payload: Any = None


class _LogToQueue(logging.Handler):
    """Every log record of the process onto /log (only enqueued here; converted on the converter thread)."""

    def __init__(self, put: Callable[[Item], None]):
        super().__init__(logging.INFO)
        self._put = put

    def emit(self, record: logging.LogRecord) -> None:
        try:
            msg = record.getMessage()
        except Exception:  # a bad format string must not break the caller's logging
            msg = str(record.msg)
        self._put(
            Item(
                Kind.LOG,
                time.time_ns(),
                (int(record.created * 1e9), record.levelno, record.name, msg, record.pathname, record.lineno),
            )
        )


class _Listener(ServerListener):
    """The server's callbacks (on a server thread): a new subscriber gets the description again."""

    def __init__(self, resend: Callable[[str], None]):
        self._resend = resend

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self._resend(channel.topic)


class RecordService(ServiceShell):
    """Live view (``record.foxglove``) and/or recording (``record_dir``) of one cell."""

    kind = "record"

    def __init__(
        self,
        settings: Settings,
        bus: Bus | None,
        *,
        live: bool | None = None,
        record_dir: str | Path | None = None,
        T_base_camera: np.ndarray | None = None,
        robot_status: RobotStatusSource | None = None,
        opener: Opener = open_new,
        on_stopped: Callable[[RecordingStopped], None] | None = None,
    ):
        super().__init__()
        self.settings = settings
        self.bus = bus
        rs = settings.record
        self.live = rs.foxglove.enabled if live is None else live
        directory = record_dir if record_dir is not None else rs.dir
        self.record_dir = Path(directory) if directory else None
        self.robot_status_source = robot_status
        self.opener = opener
        self.on_stopped = on_stopped
        self.keys = CellKeys(settings.cell_id)
        self.spec = get_robot(settings.robot.model)
        self.tool = tool_geometry(settings)
        self.transforms = convert.LinkTransforms(self.spec, self.tool, T_base_camera)
        self.urdf = convert.urdf_with_visuals(robot_urdf(self.spec, self.tool))
        self.server: Any = None  # foxglove WebSocketServer
        self.port = 0
        self.recorder: Recorder | None = None
        self.dropped = 0
        self.converted = 0
        self.errors = 0
        self.last_joint_seq = -1  # the header seq of the last joint state taken (converter thread)
        self._live_context: foxglove.Context | None = None
        self._live_channels: dict[Topic, foxglove.Channel] = {}
        self._queue: queue.Queue[Item] = queue.Queue(maxsize=rs.queue_size)
        self._frames: collections.deque[tuple[RGBDFrame, np.ndarray | None]] = collections.deque(
            maxlen=MAX_QUEUED_FRAMES
        )
        self._thread: threading.Thread | None = None
        self._subs: list[Any] = []
        self._handler: _LogToQueue | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._status_wanted = asyncio.Event()
        # converter-thread state
        self._last_mode: int | None = None
        self._last_tf_ns = 0
        self._last_q: np.ndarray | None = None  # the last joint state's angles (a TF out of turn)
        self._last_recorded_frame_ns: int | None = None
        self._calibration: bytes | None = None

    # ------------------------------------------------------------------ lifecycle
    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        self._loop = asyncio.get_running_loop()
        fs = self.settings.record.foxglove
        if self.record_dir is not None:
            self.recorder = Recorder(
                self.settings.record,
                self.record_dir,
                prefix=self.settings.cell_id,
                attachments={f"{self.spec.name}.urdf": ("application/xml", self.urdf.encode())},
                metadata={"cell_id": self.settings.cell_id, "robot_model": self.spec.name},
                opener=self.opener,
                on_stopped=self._recording_stopped,
                latched={Topic.ROBOT_DESCRIPTION: convert.robot_description(self.urdf)},
            )
            stack.callback(self.recorder.close)  # last: after the converter thread has stopped
        if self.live:
            self._live_context = ctx = foxglove.Context()  # held: a dropped context closes its channels
            self._live_channels = open_channels(ctx)
            try:
                self.server = foxglove.start_server(
                    name=f"pickplace {self.settings.cell_id}",
                    host=fs.host,
                    port=fs.port,
                    context=ctx,
                    server_listener=_Listener(self._on_subscribe),
                    asset_handler=self._asset,
                )
            except RuntimeError as exc:  # the SDK's FoxgloveError, e.g. the port is taken
                raise ConfigurationError(
                    f"cannot serve the Foxglove live view on {fs.host}:{fs.port}: {exc} "
                    "(--foxglove-port N picks another port, --no-foxglove turns it off)"
                ) from exc
            self.port = self.server.port
            stack.callback(self.server.stop)
            log.info("Foxglove live view on ws://%s:%d", fs.host, self.port)
        self._thread = threading.Thread(target=self._convert_loop, name="record.converter", daemon=True)
        self._thread.start()
        stack.push_async_callback(self._stop_thread)
        self._put(Item(Kind.RESEND, time.time_ns()))
        if self.bus is not None:
            self._subscribe_bus()
            stack.callback(self._undeclare)
        self._handler = _LogToQueue(self._put)
        logging.getLogger().addHandler(self._handler)
        stack.callback(logging.getLogger().removeHandler, self._handler)
        self.spawn(self._status_loop(), "robot-status")

    def links(self) -> dict[str, bool]:
        links: dict[str, bool] = {}
        if self.recorder is not None:
            links["recording"] = self.recorder.recording
        return links

    def _subscribe_bus(self) -> None:
        assert self.bus is not None
        routes = {
            self.keys.joint_states: Kind.JOINTS,
            self.keys.detected_objects: Kind.DETECTIONS,
            self.keys.task_status: Kind.TASK_STATUS,
            self.keys.pick_events: Kind.PICK,
            self.keys.task_plans: Kind.PLAN,
            self.keys.robot_status: Kind.ROBOT_STATUS,
            self.keys.camera_frames: Kind.BUS_FRAME,
        }
        for key, kind in routes.items():

            def on_sample(_key: str, payload: bytes, kind: Kind = kind) -> None:  # a Zenoh thread
                self.submit(kind, payload)

            self._subs.append(self.bus.subscribe_callback(key, on_sample))

    def _undeclare(self) -> None:
        for sub in self._subs:
            with contextlib.suppress(Exception):  # the session may be closing already
                sub.undeclare()
        self._subs.clear()

    async def _stop_thread(self) -> None:
        if self._thread is None:
            return
        while True:  # the stop marker must get in even if the queue is full
            try:
                self._queue.put_nowait(Item(Kind.STOP, time.time_ns()))
                break
            except queue.Full:
                with contextlib.suppress(queue.Empty):
                    self._queue.get_nowait()
        await asyncio.to_thread(self._thread.join)
        self._thread = None

    # ------------------------------------------------------------------ inputs (any thread)
    def _put(self, item: Item) -> None:
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.dropped += 1

    def submit(self, kind: Kind, payload: bytes, wait: bool = False) -> None:
        """What a bus subscription hands over (a serialised message of ``kind``); ``wait``: block while the
        converter is behind instead of dropping (benchmarks, replays)."""
        item = Item(kind, time.time_ns(), payload)
        if wait:
            self._queue.put(item)
        else:
            self._put(item)

    @property
    def frames_waiting(self) -> int:
        return len(self._frames)

    def offer_frame(self, frame: RGBDFrame, T_base_camera: np.ndarray | None = None) -> None:
        """A frame vision took (and the calibration it used): shown live, recorded at ``record.camera_rate_hz``."""
        self._frames.append((frame, T_base_camera))
        self._put(Item(Kind.FRAME, time.time_ns()))

    def _on_subscribe(self, topic: str) -> None:  # a server thread
        if topic in (Topic.ROBOT_DESCRIPTION, Topic.CAMERA_CALIBRATION, Topic.ROBOT_STATUS):
            self._put(Item(Kind.RESEND, time.time_ns()))

    def _asset(self, uri: str) -> bytes | None:
        return self.urdf.encode() if uri == URDF_ASSET_URI else None

    def _recording_stopped(self, event: RecordingStopped) -> None:
        if self.on_stopped is not None:
            self.on_stopped(event)

    # ------------------------------------------------------------------ robot status (event loop)
    async def _status_loop(self) -> None:
        period = self.settings.record.foxglove.robot_status_period_s
        while True:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(period):
                    await self._status_wanted.wait()
            self._status_wanted.clear()
            if self.robot_status_source is None:
                continue
            try:
                st = await self.robot_status_source()
            except Exception as exc:  # a status query that fails is shown, not fatal to the view
                st = robot_pb2.RobotStatus(connected=False, robot_model=self.spec.name)
                log.debug("robot status unavailable: %s", exc)
            self._put(Item(Kind.ROBOT_STATUS, time.time_ns(), st))

    # ------------------------------------------------------------------ converter thread
    def _emit(self, topic: Topic, payload: bytes, log_time_ns: int, record: bool = True) -> None:
        ch = self._live_channels.get(topic)
        if ch is not None:
            ch.log(payload, log_time=log_time_ns)
        if record and self.recorder is not None:
            self.recorder.log(topic, payload, log_time_ns)

    def _wanted(self, *topics: Topic, record: bool = True) -> bool:
        """Whether anyone takes these topics: a live subscriber or a recording that is still going."""
        if record and self.recorder is not None and self.recorder.recording:
            return True
        return any(t in self._live_channels and self._live_channels[t].has_sinks() for t in topics)

    def _convert_loop(self) -> None:
        while True:
            item = self._queue.get()
            if item.kind is Kind.STOP:
                return
            try:
                self._convert(item)
                self.converted += 1
            except Exception:  # one bad message must not end the view; counted and logged at debug
                self.errors += 1
                if self.errors in (1, 10) or self.errors % 1000 == 0:
                    log.warning(
                        "record: cannot convert a %s message (%d so far)",
                        item.kind.name,
                        self.errors,
                        exc_info=True,
                    )

    def _convert(self, item: Item) -> None:
        t = item.received_ns
        k = item.kind
        if k is Kind.JOINTS:
            self._joints(item.payload, t)
        elif k is Kind.DETECTIONS:
            if not self._wanted(Topic.DETECTIONS, Topic.VISION_OBJECTS):
                return
            objs = vision_pb2.DetectedObjects.FromString(item.payload)
            self._emit(Topic.VISION_OBJECTS, item.payload, t)
            size = self.settings.vision.cubes.cube_size_m
            self._emit(Topic.DETECTIONS, scene.scene_update(objs, self.transforms.camera_frame, size), t)
        elif k is Kind.TASK_STATUS:
            self._emit(Topic.TASK_STATUS, item.payload, t)
        elif k is Kind.PICK:
            self._emit(Topic.PICK_EVENTS, item.payload, t)
        elif k is Kind.ROBOT_STATUS:
            st = (
                item.payload
                if isinstance(item.payload, robot_pb2.RobotStatus)
                else (robot_pb2.RobotStatus.FromString(item.payload))
            )
            self._emit(Topic.ROBOT_STATUS, convert.robot_status_view(st), t)
        elif k is Kind.BUS_FRAME:
            self._frame(msg_to_frame(vision_pb2.RGBDFrame.FromString(item.payload)), None, t)
        elif k is Kind.FRAME:
            with contextlib.suppress(IndexError):
                frame, T = self._frames.popleft()
                self._frame(frame, T, t)
        elif k is Kind.LOG:
            if not self._wanted(Topic.LOG):
                return
            stamp, levelno, name, msg, path, line = item.payload
            self._emit(Topic.LOG, convert.log_message(stamp, levelno, name, msg, path, line), t)
        elif k is Kind.PLAN:
            self._emit(Topic.TASK_PLANS, item.payload, t)
            plan = task_pb2.TaskPlan.FromString(item.payload)
            m = self.settings.motion
            self._emit(
                Topic.PLANNING_SCENE, scene.planning_scene(list(plan.boxes), m.table_z_m, m.padding_m, t), t
            )
            if plan.tool_path:
                xyz = np.array([(p.x, p.y, p.z) for p in plan.tool_path])
                self._emit(Topic.PLAN, scene.plan_line(xyz, t, plan.label), t)
        elif k is Kind.RESEND:
            self._emit(Topic.ROBOT_DESCRIPTION, convert.robot_description(self.urdf), t, record=False)
            if self._calibration is not None:
                self._emit(Topic.CAMERA_CALIBRATION, self._calibration, t, record=False)

    def _joints(self, payload: bytes, t: int) -> None:
        self._emit(Topic.JOINT_STATES, payload, t)
        js = common_pb2.JointState.FromString(payload)
        self.last_joint_seq = js.header.seq
        self._last_q = np.asarray(js.position, dtype=float)
        rate = self.settings.record.foxglove.tf_rate_hz
        at = js.source_stamp_ns or t  # decimated on the controller's clock: the same states however loaded
        if (rate <= 0 or abs(at - self._last_tf_ns) >= 1e9 / rate) and self._wanted(Topic.TF):
            self._last_tf_ns = at
            self._emit(Topic.TF, self.transforms.message(np.asarray(js.position), js.header.stamp_ns or t), t)
        if self.settings.record.ros2_joint_states and self._wanted(Topic.ROS2_JOINT_STATES):
            self._emit(Topic.ROS2_JOINT_STATES, convert.ros2_joint_state(js), t)
        if js.robot_mode != self._last_mode:
            self._last_mode = js.robot_mode
            if self.robot_status_source is None:
                st = convert.robot_status_from_joints(js, self.spec.name)
                self._emit(Topic.ROBOT_STATUS, convert.robot_status_view(st), t)
            elif self._loop is not None:
                with contextlib.suppress(RuntimeError):  # the loop is closing
                    self._loop.call_soon_threadsafe(self._status_wanted.set)

    def _frame(self, frame: RGBDFrame, T_base_camera: np.ndarray | None, t: int) -> None:
        rs = self.settings.record
        stamp = frame.stamp_ns or t
        moved = T_base_camera is not None and (
            self.transforms.T_base_camera is None
            or not np.array_equal(self.transforms.T_base_camera, T_base_camera)
        )
        if moved:
            self.transforms.T_base_camera = np.asarray(T_base_camera, dtype=float)
        # the camera's TF names the frame its images name: a replay pairs the two by that name (as "camera"
        # beside "camera_color_optical_frame" images it found no pose and detected without one)
        renamed = bool(frame.frame_id) and frame.frame_id != self.transforms.camera_frame
        if renamed:
            self.transforms.camera_frame = frame.frame_id
        if (moved or renamed) and self._last_q is not None and self._wanted(Topic.TF):
            # the camera's pose before its first image, not at the next joint state after it
            self._emit(Topic.TF, self.transforms.message(self._last_q, stamp), t)
        live = self._wanted(Topic.CAMERA_COLOR, Topic.CAMERA_DEPTH, Topic.CAMERA_CALIBRATION, record=False)
        record = (
            self.recorder is not None
            and self.recorder.recording
            and (
                self._last_recorded_frame_ns is None
                or abs(stamp - self._last_recorded_frame_ns) >= 1e9 / rs.camera_rate_hz
            )
        )
        if not (live or record):
            return
        if record:
            self._last_recorded_frame_ns = stamp
        frame_id = frame.frame_id or self.transforms.camera_frame
        self._calibration = convert.camera_calibration(frame.intrinsics, stamp, frame_id)
        self._emit(Topic.CAMERA_CALIBRATION, self._calibration, t, record=record)
        self._emit(
            Topic.CAMERA_COLOR,
            convert.color_jpeg(frame.color, stamp, frame_id, rs.jpeg_quality),
            t,
            record=record,
        )
        if rs.depth:
            self._emit(Topic.CAMERA_DEPTH, convert.depth_raw(frame.depth, stamp, frame_id), t, record=record)
