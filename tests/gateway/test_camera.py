"""The camera panel's images (overlay, colour, depth) and the detection list, over the bus."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from pickplace.v1 import common_pb2, vision_pb2

from services.common.bus import Bus
from services.common.camera_pose import load_T_base_camera
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

        assert (await c.get("/api/v1/camera/info")).status_code == 404  # no frame yet

        bus.publish(keys.camera_frames, rgbd())
        await wait_until(lambda: gw.cell.hub.frame_count >= 1, 10, "the camera frame")
        info = (await c.get("/api/v1/camera/info")).json()  # the 3D view's frustum
        assert (info["width"], info["height"], info["fx"], info["cx"]) == (64, 48, 50, 32)
        T_file, _ = load_T_base_camera(s.vision.calibration)
        if T_file is None:
            assert info["T_base_camera"] is None
        else:
            assert np.allclose(info["T_base_camera"], T_file, atol=1e-6) and info["pose_source"]
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


def test_the_camera_pose_is_the_calibration_files_else_the_manual_one(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from services.common.errors import ConfigurationError
    from services.common.settings import CalibrationSettings

    T = np.eye(4)
    T[:3, 3] = (0.9, 0.0, 0.7)
    f = tmp_path / "cal.yaml"
    f.write_text("T_base_camera: " + str(T.tolist()) + "\ntimestamp: 2026-12-02T10:00:00+00:00\n")
    pose, source = load_T_base_camera(CalibrationSettings(file=str(f)))
    assert pose is not None and np.allclose(pose, T) and "cal.yaml" in source

    manual = CalibrationSettings(
        file=str(tmp_path / "none.yaml"), manual_translation_m=(0.93, 0, 0.66), manual_rpy_deg=(-145.4, 0, 90)
    )
    pose, source = load_T_base_camera(manual)
    assert pose is not None and np.allclose(pose[:3, 3], (0.93, 0, 0.66)) and source.startswith("manual")
    assert pose[2, 2] < 0  # the optical axis looks down at the table
    assert load_T_base_camera(CalibrationSettings(file=str(tmp_path / "none.yaml")))[0] is None

    f.write_text("T_base_camera: [[1, 2], [3, 4]]\n")
    with pytest.raises(ConfigurationError, match=r"cal\.yaml"):
        load_T_base_camera(CalibrationSettings(file=str(f)))
