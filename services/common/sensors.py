"""Sensor frame types: every RGB-D source (RealSense, the twin, replay) yields RGBDFrame.

Also their ``pickplace.v1.vision.RGBDFrame`` encoding and the loop that streams a camera onto Zenoh,
shared by the vision service and the simulated camera.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from pickplace.v1 import common_pb2, vision_pb2

from services.common.aio import first_of
from services.common.errors import InvalidFrameError, InvalidInputError

if TYPE_CHECKING:
    from services.common.bus import Bus


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of the colour stream (depth is aligned to it)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def validate(self) -> CameraIntrinsics:
        vals = np.array([self.fx, self.fy, self.cx, self.cy], dtype=float)
        if not np.all(np.isfinite(vals)) or self.fx <= 0 or self.fy <= 0:
            raise InvalidInputError(
                f"camera intrinsics are invalid: fx={self.fx} fy={self.fy} cx={self.cx} cy={self.cy}"
            )
        if self.width <= 0 or self.height <= 0:
            raise InvalidInputError(f"camera size must be positive, got {self.width}x{self.height}")
        return self


@dataclass(frozen=True)
class RGBDFrame:
    """One aligned RGB-D frame.

    ``color``: (H, W, 3) uint8 RGB. ``depth``: (H, W) uint16 in units of ``depth_scale`` metres
    (RealSense z16; 0 = no depth). Depth is along the optical axis (z), aligned to colour.
    """

    color: np.ndarray
    depth: np.ndarray
    intrinsics: CameraIntrinsics
    depth_scale: float = 0.001
    stamp_ns: int = 0
    frame_id: str = "camera"
    seq: int = 0
    meta: dict[str, object] = field(default_factory=dict)

    def depth_m(self) -> np.ndarray:
        return self.depth.astype(np.float32) * np.float32(self.depth_scale)

    def validate(self) -> RGBDFrame:
        intr = self.intrinsics.validate()
        shape = (intr.height, intr.width)
        if self.color.shape != (*shape, 3) or self.color.dtype != np.uint8:
            raise InvalidInputError(
                f"colour image must be uint8 {shape[0]}x{shape[1]}x3, "
                f"got {self.color.dtype} {self.color.shape}"
            )
        if self.depth.shape != shape:
            raise InvalidInputError(f"depth image must be {shape[0]}x{shape[1]}, got {self.depth.shape}")
        if not (np.isfinite(self.depth_scale) and self.depth_scale > 0):
            raise InvalidInputError(f"depth_scale must be a positive number, got {self.depth_scale}")
        return self


@runtime_checkable
class Camera(Protocol):
    """An RGB-D source. Implementations: RealSense D435i, the twin's simulated RealSense, replay."""

    @property
    def intrinsics(self) -> CameraIntrinsics: ...

    def capture(self) -> RGBDFrame:
        """Return the newest aligned frame (blocking at most the source's frame period)."""
        ...

    def close(self) -> None: ...


def frame_to_msg(frame: RGBDFrame) -> vision_pb2.RGBDFrame:
    f = frame.validate()
    i = f.intrinsics
    return vision_pb2.RGBDFrame(
        header=common_pb2.Header(stamp_ns=f.stamp_ns, frame_id=f.frame_id, seq=f.seq),
        intrinsics=vision_pb2.CameraIntrinsics(
            width=i.width, height=i.height, fx=i.fx, fy=i.fy, cx=i.cx, cy=i.cy, distortion=list(i.distortion)
        ),
        color_rgb8=np.ascontiguousarray(f.color).tobytes(),
        depth_u16=np.ascontiguousarray(f.depth.astype("<u2")).tobytes(),
        depth_scale=f.depth_scale,
    )


def msg_to_frame(msg: vision_pb2.RGBDFrame) -> RGBDFrame:
    """Decode a frame message; InvalidFrameError (a VisionError) names what does not fit."""
    i = msg.intrinsics
    w, h = int(i.width), int(i.height)
    if w <= 0 or h <= 0:
        raise InvalidFrameError(f"frame message has no image size ({w}x{h})")
    if len(msg.color_rgb8) != w * h * 3:
        raise InvalidFrameError(
            f"colour payload is {len(msg.color_rgb8)} bytes, {w}x{h} RGB8 needs {w * h * 3}"
        )
    if len(msg.depth_u16) != w * h * 2:
        raise InvalidFrameError(
            f"depth payload is {len(msg.depth_u16)} bytes, {w}x{h} uint16 needs {w * h * 2}"
        )
    intr = CameraIntrinsics(
        width=w, height=h, fx=i.fx, fy=i.fy, cx=i.cx, cy=i.cy, distortion=tuple(i.distortion)
    )
    frame = RGBDFrame(
        color=np.frombuffer(msg.color_rgb8, np.uint8).reshape(h, w, 3),
        depth=np.frombuffer(msg.depth_u16, "<u2").reshape(h, w).astype(np.uint16),
        intrinsics=intr,
        depth_scale=msg.depth_scale or 0.001,
        stamp_ns=msg.header.stamp_ns,
        frame_id=msg.header.frame_id or "camera",
        seq=msg.header.seq,
    )
    try:
        return frame.validate()
    except InvalidInputError as exc:
        raise InvalidFrameError(str(exc)) from exc


async def publish_camera_frames(
    camera: Camera,
    bus: Bus,
    key: str,
    rate_hz: float,
    stop: asyncio.Event,
    wanted: asyncio.Event | None = None,
    paused: Callable[[], bool] | None = None,
) -> int:
    """Stream a camera's frames onto Zenoh (for ``vision.camera.source: bus`` consumers); returns the
    count. ``wanted`` set: the next frame is taken at once instead of at the end of the period;
    ``paused()`` true: a period passes without a frame (one that is wanted is still taken)."""
    period = 1.0 / rate_hz
    n = 0
    while not stop.is_set():
        t0 = time.monotonic()
        asked = wanted is not None and wanted.is_set()
        if wanted is not None:
            wanted.clear()  # a request from here on asks for a frame after this one
        if asked or paused is None or not paused():
            frame = await asyncio.to_thread(camera.capture)
            bus.publish(key, frame_to_msg(frame))
            n += 1
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(max(0.0, period - (time.monotonic() - t0))):
                await first_of(stop, wanted)
    return n


def write_intrinsics(directory: Path, intr: CameraIntrinsics, depth_scale: float) -> Path:
    """``intrinsics.json`` of a recorded frame set (the replay camera and the twin's datasets write it)."""
    path = directory / "intrinsics.json"
    path.write_text(
        json.dumps(
            {
                "width": intr.width,
                "height": intr.height,
                "fx": intr.fx,
                "fy": intr.fy,
                "cx": intr.cx,
                "cy": intr.cy,
                "distortion": list(intr.distortion),
                "depth_scale": depth_scale,
                "model": "pinhole",
            },
            indent=2,
        )
    )
    return path
