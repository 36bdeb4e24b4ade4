"""The vision service over a real loopback gRPC channel and Zenoh session; camera sources."""

from __future__ import annotations

import asyncio
import sys
import threading
import time
import types

import numpy as np
import pytest
from pickplace.v1 import task_pb2, vision_pb2, vision_pb2_grpc
from prometheus_client import CollectorRegistry

from services.common.bus import Bus
from services.common.camera_pose import load_T_base_camera
from services.common.errors import (
    CameraConnectionError,
    ConfigurationError,
    InvalidFrameError,
    ObjectNotDetectedError,
)
from services.common.grpc_util import channel, rpc_errors
from services.common.keys import CellKeys
from services.common.metrics import CellMetrics
from services.common.sensors import frame_to_msg, msg_to_frame, publish_camera_frames
from services.common.settings import CameraSourceSettings
from services.vision.realsense import RealSenseCamera
from services.vision.replay import ReplayCamera, record_frames
from services.vision.service import VisionService, make_camera
from services.vision.synthetic import NoiseModel, render_scene
from services.vision.synthetic_scenes import random_scene
from tests.polling import until

pytestmark = pytest.mark.integration


class SceneCamera:
    """A camera that shows one synthetic scene, re-noised every frame."""

    def __init__(self, seed: int):
        self.scene = random_scene(seed, n_rods=1, cube_colors=("red", "green"), obstacle=True)
        self.n = 0

    @property
    def intrinsics(self):  # type: ignore[no-untyped-def]
        return self.scene.intrinsics

    def capture(self):  # type: ignore[no-untyped-def]
        self.n += 1
        frame = render_scene(self.scene, NoiseModel(), seed=self.n).frame
        return type(frame)(frame.color, frame.depth, frame.intrinsics, stamp_ns=self.n, seq=self.n)

    def close(self) -> None:
        pass


def _service(settings, bus: Bus, scene_camera: SceneCamera, own_camera: bool = False, **kw) -> VisionService:  # type: ignore[no-untyped-def]
    """A vision service on ``scene_camera``'s scene: reading that camera itself (``own_camera``), else
    the Zenoh frame stream of it."""
    return VisionService(
        settings,
        bus,
        scene_camera if own_camera else None,
        grpc_port=0,
        metrics=CellMetrics(CollectorRegistry()),
        T_base_camera=scene_camera.scene.T_base_camera,
        **kw,
    )


def _vision_settings(settings, **camera):  # type: ignore[no-untyped-def]
    v = settings.vision.model_copy(update={"camera": CameraSourceSettings(**camera)} if camera else {})
    return settings.model_copy(update={"vision": v})


async def test_detect_over_grpc_in_camera_and_base_frames(settings):
    cam = SceneCamera(31)
    T = cam.scene.T_base_camera
    metrics = CellMetrics(CollectorRegistry())
    async with (
        VisionService(
            settings, None, cam, grpc_port=0, metrics=metrics, T_base_camera=T, publish_loop=False
        ) as svc,
        channel("127.0.0.1", svc.grpc_port) as ch,
    ):
        stub = vision_pb2_grpc.VisionStub(ch)
        with pytest.raises(ObjectNotDetectedError, match="no frame has been processed"), rpc_errors():
            await stub.GetDebugImage(vision_pb2.DebugImageRequest())
        reply = await stub.Detect(vision_pb2.DetectRequest(include_debug_image=True))
        objs = reply.objects
        assert objs.rod_detected and objs.calibrated and len(objs.rods) == 1
        rod = objs.rods[0]
        truth = cam.scene.rods[0]
        centre = np.array([rod.center_base.x, rod.center_base.y, rod.center_base.z])
        assert rod.has_base and np.linalg.norm(centre - np.asarray(truth.center)) < 0.003
        axis = np.array([rod.axis_base.x, rod.axis_base.y, rod.axis_base.z])
        assert abs(axis @ truth.axis) > np.cos(np.deg2rad(2))
        cam_centre = np.array([rod.center_camera.x, rod.center_camera.y, rod.center_camera.z])
        np.testing.assert_allclose(T[:3, :3] @ cam_centre + T[:3, 3], centre, atol=1e-9)
        assert sorted(c.color_label for c in objs.cubes) == ["green", "red"]
        assert len(objs.obstacles) == 1 and objs.obstacles[0].has_base
        assert {"capture", "plane", "rod_pose", "cube_pose", "total"} <= set(objs.timings_ms)
        assert reply.debug_jpeg[:2] == b"\xff\xd8"
        image = await stub.GetDebugImage(vision_pb2.DebugImageRequest())
        assert image.jpeg == reply.debug_jpeg and image.header.seq == cam.n

        # a frame sent in the request is used instead of the camera's
        empty = random_scene(32, n_rods=0)
        frame = render_scene(empty, seed=1).frame
        reply = await stub.Detect(vision_pb2.DetectRequest(frame=frame_to_msg(frame)))
        assert not reply.objects.rod_detected and "rod not detected" in reply.objects.notes[0]

        # a malformed frame is a clear error on the client side, not a crash
        bad = frame_to_msg(frame)
        bad.depth_u16 = bad.depth_u16[:100]
        with pytest.raises(InvalidFrameError, match="depth payload"), rpc_errors():
            await stub.Detect(vision_pb2.DetectRequest(frame=bad))
        zero = frame_to_msg(frame)
        zero.depth_u16 = bytes(len(zero.depth_u16))
        with pytest.raises(InvalidFrameError, match="no valid pixels"), rpc_errors():
            await stub.Detect(vision_pb2.DetectRequest(frame=zero))

    samples = {
        (s.labels.get("stage"), s.name): s.value for m in metrics.registry.collect() for s in m.samples
    }
    for stage in ("capture", "segmentation", "pose", "total"):
        assert samples[(stage, "vision_latency_seconds_count")] >= 2


async def test_publishes_detections_from_the_zenoh_frame_stream(settings):
    cam = SceneCamera(33)
    keys = CellKeys(settings.cell_id)
    async with Bus(settings.zenoh) as bus:
        objects = bus.subscribe(keys.detected_objects, vision_pb2.DetectedObjects)
        images = bus.subscribe(keys.vision_debug_image, vision_pb2.DebugImage)
        svc = _service(settings, bus, cam)
        stop = asyncio.Event()
        async with svc:
            feeder = asyncio.create_task(publish_camera_frames(cam, bus, keys.camera_frames, 5.0, stop))
            msg = await objects.get(timeout_s=20.0)
            img = await images.get(timeout_s=20.0)
            stop.set()
            await feeder
        objects.close()
        images.close()
    assert msg.rod_detected and msg.calibrated and len(msg.cubes) == 2
    assert msg.header.seq >= 1 and img.jpeg[:2] == b"\xff\xd8"
    assert svc.published >= 1


async def test_a_detection_asks_the_frame_stream_for_its_frame(settings):
    """A stream that renders every 100 s (as the twin does at vision.rate_hz, to spare the CPU) gives
    the Detect call its frame at once: the call asks for one (CellKeys.camera_frame_requests)."""
    cam = SceneCamera(34)
    keys = CellKeys(settings.cell_id)
    loop = asyncio.get_running_loop()
    wanted, stop = asyncio.Event(), asyncio.Event()
    async with Bus(settings.zenoh) as bus:
        requests = bus.subscribe_callback(
            keys.camera_frame_requests, lambda _k, _p: loop.call_soon_threadsafe(wanted.set)
        )
        svc = _service(settings, bus, cam, publish_loop=False)
        async with svc, channel("127.0.0.1", svc.grpc_port) as ch:
            feeder = asyncio.create_task(
                publish_camera_frames(cam, bus, keys.camera_frames, 0.01, stop, wanted)
            )
            await until(lambda: svc._bus_frame is not None, "the stream's first frame at the service")
            stub = vision_pb2_grpc.VisionStub(ch)
            reply = await stub.Detect(vision_pb2.DetectRequest(), timeout=30.0)
            stop.set()
            await feeder
        requests.undeclare()
    assert reply.objects.rod_detected
    assert reply.objects.header.seq >= 2 and cam.n >= 2  # a frame after the first, 100 s early


async def test_the_live_loop_gives_way_to_a_running_cycle(settings):
    """While the task says a cycle is under way the loop detects nothing (the cycle's own Detect calls
    still are, and are published); once it says the cycle is over, the loop goes on."""
    cam = SceneCamera(35)
    keys = CellKeys(settings.cell_id)
    s = settings.model_copy(update={"vision": settings.vision.model_copy(update={"rate_hz": 20.0})})
    active = True

    async def task_status(bus: Bus) -> None:
        while True:
            bus.publish(keys.task_status, task_pb2.TaskStatus(state="PLAN", cycle_active=active))
            await asyncio.sleep(0.1)

    async with Bus(s.zenoh) as bus:
        svc = _service(s, bus, cam, own_camera=True)
        async with svc, channel("127.0.0.1", svc.grpc_port) as ch:
            status = asyncio.create_task(task_status(bus))
            try:
                await until(lambda: svc.paused_periods >= 1, "the loop to pause")
                published, captured = svc.published, cam.n
                await until(lambda: svc.paused_periods >= 6, "more paused periods")
                assert (svc.published, cam.n) == (published, captured)  # nothing while paused
                reply = await vision_pb2_grpc.VisionStub(ch).Detect(vision_pb2.DetectRequest(), timeout=30.0)
                assert reply.objects.rod_detected
                assert (svc.published, cam.n) == (published + 1, captured + 1)  # the cycle's own: published
                active = False
                await until(lambda: svc.published >= published + 3, "the loop to go on")
            finally:
                status.cancel()


class _LiveFrameDuringDetect(SceneCamera):
    """The live loop's frame arrives while a Detect call is under way: its capture returns only once the
    call's own capture began, and the call's waits until the loop has dealt with that frame."""

    def __init__(self, seed: int):
        super().__init__(seed)
        self.svc: VisionService | None = None
        self.live_waiting = threading.Event()
        self.asked = threading.Event()
        self.calls = 0

    def capture(self):  # type: ignore[no-untyped-def]
        self.calls += 1
        if self.calls == 1:  # the live loop's
            self.live_waiting.set()
            assert self.asked.wait(10.0)
        elif self.calls == 2:  # the Detect call's
            self.asked.set()
            svc = self.svc
            assert svc is not None
            deadline = time.monotonic() + 10.0  # a thread of the camera: no event loop here
            while svc.dropped_frames == 0 and svc.published == 0 and time.monotonic() < deadline:
                time.sleep(0.005)
        return super().capture()


async def test_a_live_frame_taken_while_a_detect_call_waits_is_not_detected(settings):
    """The task's DETECT does not share the CPU with a detection of the live loop: a frame the loop took
    while a Detect call was under way is dropped (the call's own detection is published instead)."""
    cam = _LiveFrameDuringDetect(36)
    s = settings.model_copy(update={"vision": settings.vision.model_copy(update={"rate_hz": 20.0})})
    async with Bus(s.zenoh) as bus:
        svc = _service(s, bus, cam, own_camera=True)
        cam.svc = svc
        async with svc, channel("127.0.0.1", svc.grpc_port) as ch:
            await until(cam.live_waiting.is_set, "the live loop to take a frame")
            reply = await vision_pb2_grpc.VisionStub(ch).Detect(vision_pb2.DetectRequest(), timeout=30.0)
            assert reply.objects.rod_detected
            assert svc.dropped_frames == 1
            assert svc.published == 1  # the Detect call's, not the loop's
            await until(lambda: svc.published >= 2, "the loop to go on")  # nothing else holds it back


async def test_without_a_frame_source_detect_says_so(settings):
    async with (
        VisionService(
            settings, None, None, grpc_port=0, metrics=CellMetrics(CollectorRegistry()), publish_loop=False
        ) as svc,
        channel("127.0.0.1", svc.grpc_port) as ch,
    ):
        stub = vision_pb2_grpc.VisionStub(ch)
        with pytest.raises(CameraConnectionError, match="no camera"), rpc_errors():
            await stub.Detect(vision_pb2.DetectRequest())


def test_frame_message_round_trip():
    frame = render_scene(random_scene(34, n_rods=1), seed=3).frame
    back = msg_to_frame(frame_to_msg(frame))
    np.testing.assert_array_equal(back.color, frame.color)
    np.testing.assert_array_equal(back.depth, frame.depth)
    assert back.intrinsics == frame.intrinsics and back.depth_scale == frame.depth_scale
    msg = frame_to_msg(frame)
    msg.intrinsics.fx = float("nan")
    with pytest.raises(InvalidFrameError, match="intrinsics"):
        msg_to_frame(msg)


def test_record_and_replay_round_trip(tmp_path):
    cam = SceneCamera(35)
    record_frames(cam, tmp_path / "rec", 3)
    replay = ReplayCamera(tmp_path / "rec", loop=False)
    assert len(replay) == 3 and replay.intrinsics == cam.intrinsics and replay.ground_truth is None
    originals = [render_scene(cam.scene, NoiseModel(), seed=k).frame for k in (1, 2, 3)]
    for original in originals:
        frame = replay.capture()
        np.testing.assert_array_equal(frame.color, original.color)
        np.testing.assert_array_equal(frame.depth, original.depth)
    with pytest.raises(CameraConnectionError, match="end of the recording"):
        replay.capture()
    with pytest.raises(Exception, match="already holds recorded frames"):
        record_frames(cam, tmp_path / "rec", 1)


def test_replay_source_from_settings_and_its_errors(tmp_path):
    record_frames(SceneCamera(36), tmp_path / "rec", 2)
    cam = make_camera(CameraSourceSettings(source="replay", replay_dir=str(tmp_path / "rec")))
    assert isinstance(cam, ReplayCamera) and cam.capture().seq == 1
    with pytest.raises(ConfigurationError, match="replay_dir"):
        make_camera(CameraSourceSettings(source="replay"))
    with pytest.raises(CameraConnectionError, match="does not exist"):
        ReplayCamera(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(CameraConnectionError, match=r"intrinsics\.json"):
        ReplayCamera(tmp_path / "empty")
    assert make_camera(CameraSourceSettings(source="bus")) is None


def test_realsense_errors_are_clear(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)  # not installed
    with pytest.raises(CameraConnectionError, match=r"pickplace\[realsense\]"):
        RealSenseCamera.open(CameraSourceSettings(source="realsense"))

    class _Context:
        def query_devices(self):  # type: ignore[no-untyped-def]
            return []

    fake = types.SimpleNamespace(context=_Context)
    monkeypatch.setitem(sys.modules, "pyrealsense2", fake)
    with pytest.raises(CameraConnectionError, match="no RealSense camera attached"):
        RealSenseCamera.open(CameraSourceSettings(source="realsense"))
    with pytest.raises(CameraConnectionError, match="not started"):
        RealSenseCamera(CameraSourceSettings()).capture()


def test_calibration_source_precedence(tmp_path):
    from services.common.settings import CalibrationSettings
    from services.vision.calibration import calibration_record, write_calibration

    none = CalibrationSettings(file=str(tmp_path / "missing.yaml"))
    assert load_T_base_camera(none) == (None, "none (camera-frame results only)")
    manual = CalibrationSettings(
        file=str(tmp_path / "missing.yaml"),
        manual_translation_m=(0.9, 0.0, 0.6),
        manual_rpy_deg=(-145.0, 0.0, 90.0),
    )
    T, source = load_T_base_camera(manual)
    assert T is not None and source.startswith("manual") and np.allclose(T[:3, 3], [0.9, 0.0, 0.6])
    T_file = np.eye(4)
    T_file[:3, 3] = [1.0, 0.1, 0.7]
    write_calibration(tmp_path / "cal.yaml", calibration_record(T_file, method="test"))
    from_file = manual.model_copy(update={"file": str(tmp_path / "cal.yaml")})
    T, source = load_T_base_camera(from_file)
    assert source.startswith("calibration file") and np.allclose(T, T_file)


class _HeldRodCamera:
    """A camera that shows a rod held upright, leaning 2°."""

    def __init__(self) -> None:
        from tests.vision.held_rod_scene import held_rod_scene

        self.scene = held_rod_scene(2.0, 30.0, noise_m=0.001)
        self.n = 0

    @property
    def intrinsics(self):  # type: ignore[no-untyped-def]
        return self.scene.frame.intrinsics

    def capture(self):  # type: ignore[no-untyped-def]
        self.n += 1
        f = self.scene.frame
        return type(f)(f.color, f.depth, f.intrinsics, f.depth_scale, stamp_ns=self.n, seq=self.n)

    def close(self) -> None:
        pass


async def test_a_held_rods_axis_over_grpc_on_a_fresh_frame_and_its_errors(settings):
    from services.common.errors import InvalidInputError
    from services.vision.messages import vec3
    from tests.vision.held_rod_scene import region

    cam = _HeldRodCamera()
    look = region()
    request = vision_pb2.MeasureHeldRodRequest(
        point_base=vec3(look.point),
        direction_base=vec3(look.direction),
        search_radius_m=look.radius_m,
        along_min_m=look.along_min_m,
        along_max_m=look.along_max_m,
        skip_min_m=look.skip_min_m,
        skip_max_m=look.skip_max_m,
        rod_diameter_m=0.022,
    )
    async with (
        VisionService(
            settings,
            None,
            cam,
            grpc_port=0,
            metrics=CellMetrics(CollectorRegistry()),
            T_base_camera=cam.scene.T_base_camera,
            publish_loop=False,
        ) as svc,
        channel("127.0.0.1", svc.grpc_port) as ch,
    ):
        stub = vision_pb2_grpc.VisionStub(ch)
        reply = await stub.MeasureHeldRod(request)
        direction = np.array([reply.direction_base.x, reply.direction_base.y, reply.direction_base.z])
        assert float(direction @ cam.scene.direction) > np.cos(np.deg2rad(0.3))
        assert abs(reply.tilt_deg - 2.0) < 0.3 and reply.n_points > 200 and reply.span_m > 0.15
        assert reply.header.seq == cam.n == 1  # measured on a frame taken for it
        away = vision_pb2.MeasureHeldRodRequest()
        away.CopyFrom(request)
        away.point_base.y += 0.3
        with pytest.raises(ObjectNotDetectedError, match="depth points where it should hang"), rpc_errors():
            await stub.MeasureHeldRod(away)
        no_way = vision_pb2.MeasureHeldRodRequest()
        no_way.CopyFrom(request)
        no_way.direction_base.CopyFrom(vision_pb2.Vec3())
        with pytest.raises(InvalidInputError, match="direction must not be zero"), rpc_errors():
            await stub.MeasureHeldRod(no_way)
