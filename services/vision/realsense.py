"""Intel RealSense D435i camera source (pyrealsense2, the optional ``realsense`` extra).

Colour (RGB8) and depth (Z16) streams at the configured size and rate, depth
aligned to colour (``rs.align``), the colour stream's intrinsics, the depth
unit from the device. Use :meth:`RealSenseCamera.open` (or ``with``); the
constructor does no I/O.
"""

from __future__ import annotations

import importlib
import time
from types import ModuleType
from typing import Any

import numpy as np

from services.common.errors import CameraConnectionError
from services.common.sensors import CameraIntrinsics, RGBDFrame
from services.common.settings import CameraSourceSettings

FRAME_TIMEOUT_MS = 2000


def _import_rs() -> ModuleType:
    try:
        return importlib.import_module("pyrealsense2")
    except ImportError as exc:
        raise CameraConnectionError(
            "pyrealsense2 is not installed: install the camera extra with pip install 'pickplace[realsense]'"
        ) from exc


class RealSenseCamera:
    """A D435i (or any RealSense with colour + depth) as a :class:`~services.common.sensors.Camera`."""

    def __init__(self, settings: CameraSourceSettings):
        self.settings = settings
        self._rs: ModuleType | None = None
        self._pipeline: Any = None
        self._align: Any = None
        self._intr: CameraIntrinsics | None = None
        self._depth_scale = 0.001
        self._seq = 0
        self.serial = ""

    @classmethod
    def open(cls, settings: CameraSourceSettings) -> RealSenseCamera:
        cam = cls(settings)
        cam.start()
        return cam

    def __enter__(self) -> RealSenseCamera:
        if self._pipeline is None:
            self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        if self._pipeline is not None:
            raise CameraConnectionError("RealSense camera already started")
        rs = _import_rs()
        devices = list(rs.context().query_devices())
        serials = [d.get_info(rs.camera_info.serial_number) for d in devices]
        if not serials:
            raise CameraConnectionError("no RealSense camera attached (check the USB 3 cable and udev rules)")
        s = self.settings
        if s.serial and s.serial not in serials:
            raise CameraConnectionError(f"RealSense {s.serial!r} not found; attached: {serials}")
        self.serial = s.serial or serials[0]
        cfg = rs.config()
        cfg.enable_device(self.serial)
        cfg.enable_stream(rs.stream.color, s.width, s.height, rs.format.rgb8, s.fps)
        cfg.enable_stream(rs.stream.depth, s.width, s.height, rs.format.z16, s.fps)
        pipeline = rs.pipeline()
        try:
            profile = pipeline.start(cfg)
        except RuntimeError as exc:
            raise CameraConnectionError(
                f"RealSense {self.serial} cannot stream {s.width}x{s.height}@{s.fps}: {exc}"
            ) from exc
        self._depth_scale = float(profile.get_device().first_depth_sensor().get_depth_scale())
        ci = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
        self._intr = CameraIntrinsics(
            width=ci.width,
            height=ci.height,
            fx=ci.fx,
            fy=ci.fy,
            cx=ci.ppx,
            cy=ci.ppy,
            distortion=tuple(float(c) for c in ci.coeffs),
        ).validate()
        self._align = rs.align(rs.stream.color)
        self._pipeline = pipeline
        self._rs = rs

    @property
    def intrinsics(self) -> CameraIntrinsics:
        if self._intr is None:
            raise CameraConnectionError("RealSense camera is not started")
        return self._intr

    def capture(self) -> RGBDFrame:
        if self._pipeline is None or self._intr is None:
            raise CameraConnectionError("RealSense camera is not started")
        try:
            frames = self._pipeline.wait_for_frames(FRAME_TIMEOUT_MS)
        except RuntimeError as exc:
            raise CameraConnectionError(
                f"RealSense {self.serial}: no frame within {FRAME_TIMEOUT_MS} ms: {exc}"
            ) from exc
        aligned = self._align.process(frames)
        color, depth = aligned.get_color_frame(), aligned.get_depth_frame()
        if not color or not depth:
            raise CameraConnectionError(f"RealSense {self.serial}: incomplete frame set")
        self._seq += 1
        return RGBDFrame(
            color=np.asanyarray(color.get_data()).copy(),
            depth=np.asanyarray(depth.get_data()).copy(),
            intrinsics=self._intr,
            depth_scale=self._depth_scale,
            stamp_ns=time.time_ns(),
            frame_id="camera_color_optical_frame",
            seq=self._seq,
        )

    def close(self) -> None:
        if self._pipeline is not None:
            try:
                self._pipeline.stop()
            finally:
                self._pipeline = None
