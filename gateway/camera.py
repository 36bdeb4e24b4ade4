"""The camera panel's images: the vision overlay as published, or the camera's newest frame as colour
or as a false-colour depth map, encoded on demand (at the rate the dashboard asks, not the camera's)."""

from __future__ import annotations

from enum import StrEnum

import cv2
import numpy as np
from pickplace.v1 import vision_pb2

from services.common.errors import InvalidInputError
from services.common.sensors import CameraIntrinsics, RGBDFrame

DEPTH_RANGE_M = (0.2, 3.0)  # depths a D435i reports reliably; the colour map spans this frame's share
JPEG_QUALITY = 85


class CameraView(StrEnum):
    OVERLAY = "overlay"  # vision's debug image: detections drawn on the colour frame
    COLOR = "color"
    DEPTH = "depth"


def frame_jpeg(payload: bytes, view: CameraView) -> bytes:
    """JPEG of one serialised RGBDFrame, as colour or as depth (turbo colour map, black = no depth)."""
    frame = vision_pb2.RGBDFrame.FromString(payload)
    w, h = frame.intrinsics.width, frame.intrinsics.height
    if w <= 0 or h <= 0:
        raise InvalidInputError(f"camera frame without a size ({w}x{h})")
    if view is CameraView.COLOR:
        if len(frame.color_rgb8) != w * h * 3:
            raise InvalidInputError(f"colour image of {len(frame.color_rgb8)} bytes for {w}x{h}")
        return image_jpeg(np.frombuffer(frame.color_rgb8, np.uint8).reshape(h, w, 3), None, 0.0, view)
    if len(frame.depth_u16) != w * h * 2:
        raise InvalidInputError(f"depth image of {len(frame.depth_u16)} bytes for {w}x{h}")
    depth = np.frombuffer(frame.depth_u16, "<u2").reshape(h, w)
    return image_jpeg(None, depth, frame.depth_scale or 1e-3, view)


def sensor_frame_jpeg(frame: RGBDFrame, view: CameraView) -> bytes:
    """The same, from an in-process frame (the embedded cell's camera)."""
    return image_jpeg(frame.color, frame.depth, frame.depth_scale, view)


def image_jpeg(
    color_rgb: np.ndarray | None, depth: np.ndarray | None, scale: float, view: CameraView
) -> bytes:
    if view is CameraView.COLOR:
        if color_rgb is None:
            raise InvalidInputError("no colour image in the frame")
        img = cv2.cvtColor(color_rgb, cv2.COLOR_RGB2BGR)
    else:
        if depth is None:
            raise InvalidInputError("no depth image in the frame")
        z = depth.astype(np.float32) * np.float32(scale)
        valid = z[(z > DEPTH_RANGE_M[0]) & (z < DEPTH_RANGE_M[1])]
        # the colour map spans what this frame sees (2nd-98th percentile), so a table scene has contrast
        lo, hi = np.percentile(valid, [2, 98]) if valid.size > 100 else DEPTH_RANGE_M
        hi = max(float(hi), float(lo) + 0.05)
        scaled = np.clip((z - lo) / (hi - lo), 0, 1)
        img = cv2.applyColorMap((255 * (1 - scaled)).astype(np.uint8), cv2.COLORMAP_TURBO)
        img[z <= 0] = 0
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise InvalidInputError("camera frame could not be encoded")
    return bytes(buf.tobytes())


def detections_json(msg: vision_pb2.DetectedObjects) -> dict[str, object]:
    """What the dashboard lists: each object with its kind, colour, confidence or fit, base-frame place."""

    def vec(v: vision_pb2.Vec3) -> list[float]:
        return [round(v.x, 4), round(v.y, 4), round(v.z, 4)]

    rods = [
        {
            "kind": "rod",
            "confidence": round(r.confidence, 3),
            "length_m": round(r.length_m, 4),
            "method": r.method,
            "base": vec(r.center_base) if r.has_base else None,
            "axis": vec(r.axis_base) if r.has_base else None,
            "diameter_m": round(r.diameter_m, 4),
        }
        for r in msg.rods
    ]
    cubes = [
        {
            "kind": "cube",
            "color": c.color_label,
            "visibility": vision_pb2.Visibility.Name(c.visibility).removeprefix("VISIBILITY_").lower(),
            "hidden_fraction": round(c.hidden_fraction, 3),
            "fit_rms_mm": round(c.fit_rms_m * 1e3, 2),
            "base": vec(c.centroid_base) if c.has_base else None,
        }
        for c in msg.cubes
    ]
    boxes = [
        {
            "kind": "obstacle",
            "color": b.color_label,
            "recognised": b.recognised,
            "base": [vec(b.base.min), vec(b.base.max)] if b.has_base else None,
        }
        for b in msg.obstacles
    ]
    return {
        "seq": msg.header.seq,
        "stamp_ns": msg.header.stamp_ns,
        "objects": rods + cubes + boxes,
        "notes": list(msg.notes),
        "total_ms": round(msg.timings_ms.get("total", 0.0), 1),
        "calibrated": msg.calibrated,
    }


def frame_intrinsics(payload: bytes) -> CameraIntrinsics:
    """The pinhole of one serialised RGBDFrame."""
    k = vision_pb2.RGBDFrame.FromString(payload).intrinsics
    if k.width <= 0 or k.height <= 0 or k.fx <= 0 or k.fy <= 0:
        raise InvalidInputError(
            f"camera frame without intrinsics ({k.width}x{k.height}, fx {k.fx}, fy {k.fy})"
        )
    return CameraIntrinsics(k.width, k.height, k.fx, k.fy, k.cx, k.cy, tuple(k.distortion))
