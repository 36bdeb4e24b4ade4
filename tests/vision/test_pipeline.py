"""Frame validation, determinism, timings, the debug overlay, and the synthetic renderer itself."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from services.common.errors import InvalidFrameError, InvalidInputError, VisionError
from services.common.sensors import CameraIntrinsics, RGBDFrame
from services.common.settings import VisionSettings
from services.vision.overlay import draw_detections, encode_jpeg, overlay_jpeg
from services.vision.pipeline import VisionPipeline, validate_frame
from services.vision.synthetic import NoiseModel, render_scene
from services.vision.synthetic_scenes import random_scene


@pytest.fixture(scope="module")
def scene_and_frame():
    scene = random_scene(21, n_rods=1, cube_colors=("red", "blue"), obstacle=True)
    return scene, render_scene(scene, NoiseModel(), seed=21).frame


def _bad(frame: RGBDFrame, **changes) -> RGBDFrame:
    return dataclasses.replace(frame, **changes)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda f: _bad(f, color=f.color[:, :, :2]), "colour image"),
        (lambda f: _bad(f, color=f.color.astype(np.float32)), "colour image"),
        (lambda f: _bad(f, depth=f.depth[:100]), "depth image must be"),
        (lambda f: _bad(f, depth=np.zeros_like(f.depth)), "no valid pixels"),
        (
            lambda f: _bad(
                f,
                depth=np.where(np.arange(f.depth.size).reshape(f.depth.shape) % 100 == 0, f.depth, 0).astype(
                    np.uint16
                ),
            ),
            "valid",
        ),
        (lambda f: _bad(f, intrinsics=dataclasses.replace(f.intrinsics, fx=float("nan"))), "intrinsics"),
        (lambda f: _bad(f, intrinsics=dataclasses.replace(f.intrinsics, fy=-1.0)), "intrinsics"),
        (lambda f: _bad(f, depth_scale=float("nan")), "depth_scale"),
    ],
)
def test_bad_frames_raise_a_clear_vision_error(scene_and_frame, change, message):
    _, frame = scene_and_frame
    with pytest.raises(InvalidFrameError, match=message) as info:
        VisionPipeline().detect(change(frame))
    assert isinstance(info.value, VisionError) and isinstance(info.value, InvalidInputError)


def test_not_a_frame_and_bad_transform_are_rejected(scene_and_frame):
    _, frame = scene_and_frame
    with pytest.raises(InvalidFrameError, match="RGBDFrame"):
        validate_frame("frame.png")  # type: ignore[arg-type]
    T = np.eye(4)
    T[0, 0] = 2.0
    with pytest.raises(InvalidInputError, match="T_base_camera"):
        VisionPipeline().detect(frame, T)


def test_a_wall_with_no_table_is_a_vision_error():
    intr = CameraIntrinsics(width=64, height=48, fx=60.0, fy=60.0, cx=32.0, cy=24.0)
    rng = np.random.default_rng(0)
    depth = rng.uniform(300, 3000, (48, 64)).astype(np.uint16)  # no plane anywhere
    frame = RGBDFrame(color=np.zeros((48, 64, 3), np.uint8), depth=depth, intrinsics=intr)
    with pytest.raises(VisionError, match="no table plane"):
        VisionPipeline().detect(frame)


def test_detection_is_deterministic_and_timed(scene_and_frame):
    scene, frame = scene_and_frame
    pipe = VisionPipeline()
    a = pipe.detect(frame, scene.T_base_camera)
    b = pipe.detect(frame, scene.T_base_camera)
    np.testing.assert_array_equal(a.rods[0].center_cam, b.rods[0].center_cam)
    assert [c.color_label for c in a.cubes] == [c.color_label for c in b.cubes]
    for key in ("plane", "rod_segmentation", "rod_pose", "cube_segmentation", "cube_pose", "total"):
        assert a.timings_ms[key] >= 0.0
    assert a.table is not None and a.table.d > 0
    np.testing.assert_array_equal(a.T_base_camera, scene.T_base_camera)


def test_stages_can_be_switched_off(scene_and_frame):
    scene, frame = scene_and_frame
    only_rods = VisionPipeline(VisionSettings(detect_cubes=False)).detect(frame, scene.T_base_camera)
    assert (
        only_rods.cubes == () and len(only_rods.rods) == 1 and "cube_segmentation" not in only_rods.timings_ms
    )
    only_cubes = VisionPipeline(VisionSettings(detect_rods=False)).detect(frame, scene.T_base_camera)
    assert only_cubes.rods == () and len(only_cubes.cubes) == 2 and "rod_pose" not in only_cubes.timings_ms


def test_overlay_is_a_decodable_jpeg_with_the_detections_drawn(scene_and_frame):
    scene, frame = scene_and_frame
    result = VisionPipeline().detect(frame, scene.T_base_camera)
    drawn = draw_detections(frame.color, result)
    plain = cv2.cvtColor(frame.color, cv2.COLOR_RGB2BGR)
    assert drawn.shape == plain.shape
    u, v = np.rint(result.rods[0].endpoints_px.mean(axis=0)).astype(int)
    assert np.any(
        drawn[v - 3 : v + 4, u - 3 : u + 4] != plain[v - 3 : v + 4, u - 3 : u + 4]
    )  # the rod marker
    jpeg = overlay_jpeg(frame.color, result, quality=70)
    assert jpeg[:2] == b"\xff\xd8"
    decoded = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == plain.shape
    with pytest.raises(InvalidInputError, match="quality"):
        encode_jpeg(drawn, quality=0)
    with pytest.raises(InvalidInputError, match="uint8"):
        draw_detections(frame.color.astype(float), result)


def test_renderer_depth_matches_the_table_plane_with_noise_off():
    scene = random_scene(4, n_rods=0)
    rendered = render_scene(scene, NoiseModel.off())
    depth = rendered.frame.depth_m()
    on_table = rendered.labels == 1
    rows, cols = np.nonzero(on_table)
    intr = scene.intrinsics
    rays = np.column_stack([(cols - intr.cx) / intr.fx, (rows - intr.cy) / intr.fy, np.ones(len(rows))])
    R, o = scene.T_base_camera[:3, :3], scene.T_base_camera[:3, 3]
    analytic = -o[2] / (rays @ R.T)[:, 2]  # depth where each ray meets z = 0
    assert np.max(np.abs(depth[rows, cols] - analytic)) <= 0.0005 + 1e-6  # mm quantisation


def test_renderer_is_seeded_and_noise_makes_holes_on_the_rod():
    scene = random_scene(9, n_rods=1)
    a = render_scene(scene, NoiseModel(), seed=5)
    b = render_scene(scene, NoiseModel(), seed=5)
    c = render_scene(scene, NoiseModel(), seed=6)
    np.testing.assert_array_equal(a.frame.depth, b.frame.depth)
    np.testing.assert_array_equal(a.frame.color, b.frame.color)
    assert np.any(a.frame.depth != c.frame.depth)
    rod = a.labels == 10
    holes = np.mean(a.frame.depth[rod] == 0)
    assert 0.2 < holes < 0.6
    clean = render_scene(scene, NoiseModel.off())
    assert np.all(clean.frame.depth[rod] > 0)


def test_depth_outside_the_working_range_is_a_clear_error():
    intr = CameraIntrinsics(width=64, height=48, fx=60.0, fy=60.0, cx=32.0, cy=24.0)
    frame = RGBDFrame(
        color=np.zeros((48, 64, 3), np.uint8), depth=np.full((48, 64), 5000, np.uint16), intrinsics=intr
    )
    with pytest.raises(VisionError, match="no depth between"):
        VisionPipeline().detect(frame)
