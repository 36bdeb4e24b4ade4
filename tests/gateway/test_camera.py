"""The camera panel's images (overlay, colour, depth) and the detection list, over the bus."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from pickplace.v1 import common_pb2, vision_pb2

from services.common.bus import Bus
from services.common.keys import CellKeys
from tests.gateway.conftest import gateway_settings, migrate_up, running_gateway, wait_until

pytestmark = pytest.mark.integration


def rgbd(w: int = 64, h: int = 48) -> vision_pb2.RGBDFrame:
    color = np.zeros((h, w, 3), np.uint8)
    color[:, : w // 2] = (255, 0, 0)  # left half red (RGB)
    depth = np.tile(np.linspace(600, 1000, w).astype("<u2"), (h, 1))  # nearer on the left
    depth[:8, :8] = 0  # no depth
    return vision_pb2.RGBDFrame(
        header=common_pb2.Header(seq=1),
        intrinsics=vision_pb2.CameraIntrinsics(width=w, height=h, fx=50, fy=50, cx=w / 2, cy=h / 2),
        color_rgb8=color.tobytes(),
        depth_u16=depth.tobytes(),
        depth_scale=0.001,
    )


async def test_colour_depth_views_and_detections(settings, sqlite_db, tmp_path) -> None:  # type: ignore[no-untyped-def]
    await migrate_up(sqlite_db)
    s = gateway_settings(settings, sqlite_db, tmp_path)
    keys = CellKeys(s.cell_id)
    async with Bus(s.zenoh) as bus, running_gateway(s, bus) as gw:
        c = gw.client
        r = await c.get("/api/v1/camera/latest.jpg", params={"view": "depth"})
        assert r.status_code == 404 and "camera frame" in r.json()["detail"]
        assert (await c.get("/api/v1/camera/latest.jpg", params={"view": "x-ray"})).status_code == 422

        bus.publish(keys.camera_frames, rgbd())
        await wait_until(lambda: gw.cell.hub.frame_count >= 1, 10, "the camera frame")
        r = await c.get("/api/v1/camera/latest.jpg", params={"view": "color"})
        assert r.status_code == 200 and r.headers["content-type"] == "image/jpeg"
        img = cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape == (48, 64, 3) and img[24, 10, 2] > 200 and img[24, 50, 2] < 50  # red, left (BGR)
        r = await c.get("/api/v1/camera/latest.jpg", params={"view": "depth"})
        depth = cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_COLOR)
        assert depth[3, 3].sum() < 60  # black where there is no depth
        left, right = depth[24, 12].astype(int), depth[24, 60].astype(int)
        assert np.abs(left - right).sum() > 150  # the colour map spans the frame's depths

        det = vision_pb2.DetectedObjects(header=common_pb2.Header(seq=7), calibrated=True, rod_detected=True)
        rod = det.rods.add(confidence=0.91, length_m=0.2, has_base=True)
        rod.center_base.x, rod.center_base.y, rod.center_base.z = 0.45, 0.01, 0.02
        det.cubes.add(color_label="red", visibility=vision_pb2.VISIBILITY_OCCLUDED, fit_rms_m=0.0012)
        det.timings_ms["total"] = 41.5
        bus.publish(keys.detected_objects, det)
        await wait_until(lambda: gw.cell.hub.detections is not None, 10, "the detections")
        d = gw.cell.hub.detections
        assert d["seq"] == 7 and d["total_ms"] == 41.5
        assert d["objects"][0] == {
            "kind": "rod",
            "confidence": 0.91,
            "length_m": 0.2,
            "method": "",
            "base": [0.45, 0.01, 0.02],
            "axis": [0.0, 0.0, 0.0],
            "diameter_m": 0.0,
        }
        assert d["objects"][1]["color"] == "red" and d["objects"][1]["visibility"] == "occluded"
        assert d["objects"][1]["base"] is None  # no base-frame pose without has_base
