"""The vision service: frames in, objects out — Zenoh stream, `Vision.Detect` over gRPC, debug JPEG, metrics.

A thin shell around :class:`~services.vision.pipeline.VisionPipeline`:

- frames come from a camera it owns (RealSense, replay, or one passed in — the twin's in
  ``pickplace up``), or from the Zenoh frame stream (``vision.camera.source: bus``);
- detections are published on ``CellKeys.detected_objects`` (``DetectedObjects``) at up to
  ``vision.rate_hz``, with a JPEG overlay on ``CellKeys.vision_debug_image``;
- ``Vision.Detect`` answers on demand (on a frame in the request, or the newest one);
- ``Vision.MeasureHeldRod`` fits the axis of a rod the gripper holds, on a fresh frame
  (:mod:`services.vision.held_rod`);
- per-stage latency (capture, segmentation, pose, total) goes to the ``vision_latency_seconds``
  histogram of :class:`~services.common.metrics.CellMetrics`.

The camera-to-base transform comes from the calibration file, else the manual pose in the
settings, else none (camera-frame results only, ``calibrated = false``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import Iterator
from typing import Any

import grpc
import numpy as np
from pickplace.v1 import common_pb2, vision_pb2, vision_pb2_grpc

from services.common.bus import Bus
from services.common.camera_pose import load_T_base_camera
from services.common.cycle_watch import CycleWatch, follow_cycles
from services.common.errors import (
    CameraConnectionError,
    ConfigurationError,
    InvalidInputError,
    ObjectNotDetectedError,
    VisionError,
)
from services.common.keys import CellKeys
from services.common.live_config import LiveConfig
from services.common.metrics import CellMetrics
from services.common.sensors import (
    Camera,
    CameraIntrinsics,
    RGBDFrame,
    msg_to_frame,
)
from services.common.settings import CameraSourceSettings, Settings
from services.common.shell import GrpcShell, cell_token
from services.vision.geometry import backproject
from services.vision.held_rod import HeldRodAxis, HeldRodRegion, fit_held_rod_axis, region_mask
from services.vision.messages import detections_msg, from_vec3, vec3
from services.vision.overlay import overlay_jpeg
from services.vision.pipeline import VisionPipeline, replace_timings
from services.vision.results import DetectionResult

log = logging.getLogger("pickplace.vision.service")

Array = np.ndarray

FRAME_WAIT_S = 2.0
CAPTURE_FAILURES_DOWN = 3  # frames missed in a row before health reports the frame source down


def make_camera(settings: CameraSourceSettings) -> Camera | None:
    """The camera the service owns for this source; None for sources it does not open itself."""
    if settings.source == "realsense":
        from services.vision.realsense import RealSenseCamera

        return RealSenseCamera.open(settings)
    if settings.source == "replay":
        if not settings.replay_dir:
            raise ConfigurationError(
                "vision.camera.source is 'replay' but vision.camera.replay_dir is not set"
            )
        from services.vision.replay import ReplayCamera

        return ReplayCamera(settings.replay_dir, loop=settings.replay_loop)
    return None  # "bus": frames arrive on Zenoh; "twin": the twin's camera is passed in by `pickplace up`


class VisionServicer(vision_pb2_grpc.VisionServicer):
    def __init__(self, service: VisionService):
        self.service = service

    async def Detect(
        self, request: vision_pb2.DetectRequest, context: grpc.aio.ServicerContext
    ) -> vision_pb2.DetectResponse:
        frame = msg_to_frame(request.frame) if request.HasField("frame") else None
        result, used = await self.service.detect_once(frame, prompt=True)
        response = vision_pb2.DetectResponse(objects=detections_msg(result, used.frame_id))
        if request.include_debug_image:
            response.debug_jpeg = self.service.latest_jpeg or b""
        return response

    async def GetDebugImage(
        self, request: vision_pb2.DebugImageRequest, context: grpc.aio.ServicerContext
    ) -> vision_pb2.DebugImage:
        if self.service.latest_jpeg is None:
            raise ObjectNotDetectedError("no frame has been processed yet, so there is no debug image")
        return vision_pb2.DebugImage(header=self.service.latest_header, jpeg=self.service.latest_jpeg)

    async def MeasureHeldRod(
        self, request: vision_pb2.MeasureHeldRodRequest, context: grpc.aio.ServicerContext
    ) -> vision_pb2.MeasureHeldRodResponse:
        region = HeldRodRegion(
            from_vec3(request.point_base),
            from_vec3(request.direction_base),
            request.search_radius_m,
            request.along_min_m,
            request.along_max_m,
            request.skip_min_m,
            request.skip_max_m,
        )
        if not request.rod_diameter_m > 0:
            raise InvalidInputError(f"rod_diameter_m must be > 0, got {request.rod_diameter_m}")
        axis, frame = await self.service.measure_held_rod(region, request.rod_diameter_m / 2)
        return vision_pb2.MeasureHeldRodResponse(
            header=common_pb2.Header(stamp_ns=frame.stamp_ns, frame_id=frame.frame_id, seq=frame.seq),
            direction_base=vec3(axis.direction),
            point_base=vec3(axis.point),
            n_points=axis.n_points,
            span_m=axis.span_m,
            rms_m=axis.rms_m,
            tilt_deg=axis.tilt_deg(),
        )


class VisionService(GrpcShell):
    """Owns the pipeline, the frame source, the gRPC server and the publishing loop."""

    kind = "vision"

    def __init__(
        self,
        settings: Settings,
        bus: Bus | None = None,
        camera: Camera | None = None,
        grpc_port: int | None = None,
        metrics: CellMetrics | None = None,
        T_base_camera: Array | None = None,
        publish_loop: bool = True,
    ):
        super().__init__(
            settings.grpc.host,
            settings.grpc.vision_port if grpc_port is None else grpc_port,
            cell_token(settings),
        )
        self.settings = settings
        self.bus = bus
        self.camera = camera
        self._owns_camera = False
        self.keys = CellKeys(settings.cell_id)
        self.pipeline = VisionPipeline(settings.vision)
        self.metrics = metrics or CellMetrics()
        if T_base_camera is not None:
            self.T_base_camera: Array | None = np.asarray(T_base_camera, dtype=float)
            self.calibration_source = "given"
        else:
            self.T_base_camera, self.calibration_source = load_T_base_camera(settings.vision.calibration)
        self.publish_loop = publish_loop
        self.latest_jpeg: bytes | None = None
        self.latest_header = common_pb2.Header()
        self.latest_result: DetectionResult | None = None
        self.published = 0
        self.paused_periods = 0  # live-loop periods given to a running cycle
        self.dropped_frames = 0  # live-loop frames not detected: a cycle started or asked meanwhile
        self._asked = 0  # Detect calls in progress: someone waits for them, the live loop does not
        # wall seconds spent getting the frames someone waited for (a Detect, a held-rod measure): in
        # the twin, its camera rendering them; the eval tells this apart from the cell's own compute
        self.waited_capture_s = 0.0
        self._bus_frame: RGBDFrame | None = None
        self._bus_frame_event = asyncio.Event()
        self._subscription: Any = None
        self._capture_failures = 0  # in a row: the frame source is taken as down from CAPTURE_FAILURES_DOWN
        self.live: LiveConfig | None = None
        self._detect_lock = asyncio.Lock()
        self.cycle = CycleWatch()  # the live loop pauses while the task runs a cycle

    # --- lifecycle ---------------------------------------------------------------------------------
    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        if self.camera is None:
            self.camera = await asyncio.to_thread(make_camera, self.settings.vision.camera)
            self._owns_camera = self.camera is not None
            stack.push_async_callback(self._close_own_camera)
        if self.camera is None and self.bus is not None:
            loop = asyncio.get_running_loop()

            def on_frame(_key: str, payload: bytes) -> None:  # a Zenoh thread: over to the event loop
                loop.call_soon_threadsafe(self._on_bus_frame, payload)

            self._subscription = self.bus.subscribe_callback(self.keys.camera_frames, on_frame)
            stack.callback(self._undeclare_subscription)
        if self.bus is not None:  # the live loop gives way to a running cycle
            follow_cycles(self.bus, self.settings.cell_id, self.cycle, stack)
        await self._serve_grpc(
            stack,
            lambda server: vision_pb2_grpc.add_VisionServicer_to_server(VisionServicer(self), server),
            "Vision",
        )
        if self.publish_loop and (self.camera is not None or self._subscription is not None):
            self.spawn(self._run(), "publish")
        if self.bus is not None:
            self.live = self.follow_config(self.bus, self.settings, self._on_config)
        log.info(
            "vision camera %s; calibration: %s",
            type(self.camera).__name__ if self.camera else "Zenoh frame stream",
            self.calibration_source,
        )

    def links(self) -> dict[str, bool]:
        has_source = self.camera is not None or self._subscription is not None
        return {"frame source": has_source and self._capture_failures < CAPTURE_FAILURES_DOWN}

    async def _on_config(self, new: Settings, changed: list[str]) -> None:
        """PUT /config: the rate applies from the next frame, the enabled detectors from the next detection."""
        self.settings = new
        if any(c.startswith("vision.") for c in changed):
            self.pipeline.settings = new.vision

    def _undeclare_subscription(self) -> None:
        with contextlib.suppress(Exception):  # the session may be closing already
            self._subscription.undeclare()
        self._subscription = None

    async def _close_own_camera(self) -> None:
        if self._owns_camera and self.camera is not None:
            await asyncio.to_thread(self.camera.close)
            self.camera = None

    # --- frames ------------------------------------------------------------------------------------
    def _on_bus_frame(self, payload: bytes) -> None:
        try:
            self._bus_frame = msg_to_frame(vision_pb2.RGBDFrame.FromString(payload))
        except Exception as exc:  # a bad frame on the stream must not stop the service
            log.warning("dropping an undecodable camera frame: %s", exc)
            return
        self._bus_frame_event.set()

    async def _next_frame(self, prompt: bool = False) -> tuple[RGBDFrame, float]:
        """The newest frame and how long getting it took (s)."""
        t0 = time.perf_counter()
        try:
            frame = await self._capture(prompt)
        except CameraConnectionError:
            self._capture_failures += 1
            raise
        self._capture_failures = 0
        took = time.perf_counter() - t0
        if prompt:
            self.waited_capture_s += took
        return frame, took

    async def _capture(self, prompt: bool = False) -> RGBDFrame:
        if self.camera is not None:
            return await asyncio.to_thread(self.camera.capture)
        if self._subscription is None or self.bus is None:
            raise CameraConnectionError("the vision service has no camera and no frame stream")
        self._bus_frame_event.clear()
        if prompt:  # the twin renders it at once rather than at its next period
            self.bus.publish(self.keys.camera_frame_requests, b"")
        try:
            async with asyncio.timeout(FRAME_WAIT_S):
                await self._bus_frame_event.wait()
        except TimeoutError as exc:
            raise CameraConnectionError(
                f"no camera frame on {self.keys.camera_frames} within {FRAME_WAIT_S} s"
            ) from exc
        assert self._bus_frame is not None
        return self._bus_frame

    @contextlib.contextmanager
    def _waited_for(self, prompt: bool) -> Iterator[None]:
        """A call someone waits for (``prompt``) is under way: the live loop leaves the CPU to it."""
        self._asked += prompt
        try:
            yield
        finally:
            self._asked -= prompt

    # --- a held rod --------------------------------------------------------------------------------
    async def measure_held_rod(
        self, region: HeldRodRegion, rod_radius_m: float
    ) -> tuple[HeldRodAxis, RGBDFrame]:
        """The axis of the rod held in ``region`` (base frame), on a frame taken now."""
        T = self.T_base_camera
        if T is None:
            raise VisionError("vision has no camera-to-base calibration; run `pickplace calibrate`")
        with self._waited_for(True):
            frame, _ = await self._next_frame(prompt=True)
            async with self._detect_lock:
                axis = await asyncio.to_thread(_fit_held_rod, frame, T, region, rod_radius_m)
        log.info(
            "held rod: %.2f° from the vertical (%d points over %.0f mm)",
            axis.tilt_deg(),
            axis.n_points,
            axis.span_m * 1e3,
        )
        return axis, frame

    # --- detection -----------------------------------------------------------------------------------
    async def detect_once(
        self, frame: RGBDFrame | None = None, prompt: bool = False, capture_s: float = 0.0
    ) -> tuple[DetectionResult, RGBDFrame]:
        """Detect on ``frame`` (or the newest one), record metrics, publish, refresh the overlay.
        ``prompt``: someone waits for it: a frame stream that takes requests is asked for a frame now,
        and the live loop leaves the CPU to it meanwhile."""
        with self._waited_for(prompt):
            if frame is None:
                frame, capture_s = await self._next_frame(prompt)
            async with self._detect_lock:  # one CPU-bound detection at a time, off the event loop
                result = await asyncio.to_thread(self.pipeline.detect, frame, self.T_base_camera)
                jpeg = await asyncio.to_thread(
                    overlay_jpeg, frame.color, result, self.settings.vision.debug_jpeg_quality
                )
        result = replace_timings(result, capture=capture_s * 1e3)
        self._observe(result)
        self.latest_result = result
        self.latest_jpeg = jpeg
        self.latest_header = common_pb2.Header(
            stamp_ns=frame.stamp_ns or time.time_ns(), frame_id=frame.frame_id, seq=frame.seq
        )
        self._publish(result, frame, jpeg)
        return result, frame

    def _observe(self, result: DetectionResult) -> None:
        t = result.timings_ms
        stages = {
            "capture": t.get("capture", 0.0),
            "segmentation": t.get("plane", 0.0)
            + t.get("rod_segmentation", 0.0)
            + t.get("cube_segmentation", 0.0),
            "pose": t.get("rod_pose", 0.0) + t.get("cube_pose", 0.0),
            "total": t.get("total", 0.0) + t.get("capture", 0.0),
        }
        for stage, ms in stages.items():
            self.metrics.vision_latency.labels(stage).observe(ms / 1e3)

    def _publish(self, result: DetectionResult, frame: RGBDFrame, jpeg: bytes) -> None:
        if self.bus is None:
            return
        try:
            self.bus.publish(self.keys.detected_objects, detections_msg(result, frame.frame_id))
            self.bus.publish(
                self.keys.vision_debug_image, vision_pb2.DebugImage(header=self.latest_header, jpeg=jpeg)
            )
            self.published += 1
        except Exception as exc:  # the bus must never break detection
            log.warning("zenoh publish failed: %s", exc)

    def _live_gives_way(self, now: float) -> bool:
        """Whether the live loop leaves the CPU to a cycle: one is under way (as the task says), or a
        Detect call waits (the task's own status may still be on its way)."""
        return self._asked > 0 or self.cycle.gives_way(now, self.settings.vision.live_during_cycle)

    async def _run(self) -> None:
        failures = 0
        while True:
            period = 1.0 / self.settings.vision.rate_hz  # read each time: PUT /config may change it
            t0 = time.monotonic()
            if self._live_gives_way(t0):
                self.paused_periods += 1  # the cycle's own detections are published meanwhile
                await asyncio.sleep(period)
                continue
            try:
                frame, capture_s = await self._next_frame()
                if self._live_gives_way(time.monotonic()):
                    # a cycle began while this frame was taken: its own detection goes first (a
                    # detection beside it took the CPU its DETECT waits for)
                    self.dropped_frames += 1
                else:
                    await self.detect_once(frame, capture_s=capture_s)
                failures = 0
            except VisionError as exc:
                failures += 1
                if failures in (1, 10) or failures % 100 == 0:  # say it, without flooding the log
                    log.warning("vision loop: %s (%d in a row)", exc, failures)
            await asyncio.sleep(max(0.0, period - (time.monotonic() - t0)))


def _fit_held_rod(
    frame: RGBDFrame, T_base_camera: Array, region: HeldRodRegion, rod_radius_m: float
) -> HeldRodAxis:
    depth_m = frame.depth.astype(np.float64) * frame.depth_scale
    points, _, _ = backproject(
        depth_m, frame.intrinsics, mask=region_mask(region, T_base_camera, frame.intrinsics)
    )
    return fit_held_rod_axis(points, T_base_camera, region, rod_radius_m)


class BusCamera:
    """The Zenoh camera-frame stream as a :class:`Camera` (for the CLI: record, calibrate, check).

    ``capture`` blocks (call it from a worker thread) until a frame newer than the last one arrives.
    """

    def __init__(self, bus: Bus, key: str, timeout_s: float = FRAME_WAIT_S):
        self._cond = threading.Condition()
        self._frame: RGBDFrame | None = None
        self._taken = 0
        self._timeout_s = timeout_s
        self._key = key
        self._sub = bus.subscribe_callback(key, self._on_frame)

    def _on_frame(self, _key: str, payload: bytes) -> None:
        try:
            frame = msg_to_frame(vision_pb2.RGBDFrame.FromString(payload))
        except VisionError as exc:
            log.warning("dropping an undecodable camera frame: %s", exc)
            return
        with self._cond:
            self._frame = frame
            self._cond.notify_all()

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self.capture(fresh=False).intrinsics

    def capture(self, fresh: bool = True) -> RGBDFrame:
        with self._cond:
            ok = self._cond.wait_for(
                lambda: self._frame is not None and (not fresh or id(self._frame) != self._taken),
                self._timeout_s,
            )
            if not ok or self._frame is None:
                raise CameraConnectionError(f"no camera frame on {self._key} within {self._timeout_s} s")
            self._taken = id(self._frame)
            return self._frame

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._sub.undeclare()


async def serve(settings: Settings, camera: Camera | None = None) -> None:
    """``pickplace serve vision``: run until cancelled."""
    async with Bus(settings.zenoh) as bus, VisionService(settings, bus, camera) as svc:
        await svc.wait()
