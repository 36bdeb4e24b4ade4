"""Seed 004 cube/obstacle pipeline on seeded synthetic scenes: centroids, colours, obstacle boxes."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.settings import CubeDetectionSettings, ObstacleRuleSettings, VisionSettings
from services.common.settings.vision import DEFAULT_COLOR_TABLE
from services.vision.cubes import classify_color
from services.vision.pipeline import VisionPipeline
from services.vision.results import Visibility
from services.vision.synthetic import (
    COLORS_RGB,
    BoxSpec,
    NoiseModel,
    SyntheticScene,
    d435_intrinsics,
    look_at_camera,
    render_scene,
)
from services.vision.synthetic_scenes import hard_case, random_scene

N_SCENES = 50
CENTROID_TOL_M = 0.005
ALL_COLOURS = ("red", "green", "blue", "black")


def test_cubes_and_obstacle_over_50_noisy_scenes():
    pipe = VisionPipeline()
    errors = []
    for seed in range(N_SCENES):
        colours = ALL_COLOURS[: 2 + seed % 3]
        scene = random_scene(seed, n_rods=seed % 2, cube_colors=colours, obstacle=seed % 5 != 4)
        result = pipe.detect(render_scene(scene, NoiseModel(), seed=seed).frame, scene.T_base_camera)
        assert len(result.cubes) == len(scene.cubes), f"seed {seed}: {result.notes}"
        for truth in scene.cubes:
            d = [np.linalg.norm(c.centroid_base - np.asarray(truth.center)) for c in result.cubes]
            match = result.cubes[int(np.argmin(d))]
            errors.append(min(d))
            assert min(d) <= CENTROID_TOL_M, f"seed {seed} {truth.color}: {min(d) * 1e3:.1f} mm"
            assert match.color_label == truth.color, f"seed {seed}: {truth.color} seen as {match.color_label}"
        assert len(result.obstacles) == len(scene.obstacles), f"seed {seed}: {result.notes}"
        for box, truth in zip(result.obstacles, scene.obstacles, strict=True):
            assert np.all(box.contains(truth.corners())), f"seed {seed}: obstacle box misses a corner"
            assert np.all(
                box.max_base - box.min_base < np.asarray(truth.size).max() * 1.5 + 0.05
            )  # and is tight
            assert box.min_base[2] <= 0.0 + 1e-3  # it stands on the table
        if scene.rods:
            assert len(result.rods) == 1  # the rod is not mistaken for a cube or obstacle
    assert np.median(errors) < 0.002


def test_cube_pose_is_the_cube_centre_not_the_visible_centroid():
    scene = random_scene(3, cube_colors=("red",))
    result = VisionPipeline().detect(render_scene(scene, NoiseModel.off(), seed=3).frame, scene.T_base_camera)
    cube = result.cubes[0]
    assert np.linalg.norm(cube.centroid_base - np.asarray(scene.cubes[0].center)) < 0.001
    assert cube.centroid_base[2] == pytest.approx(0.025, abs=0.001)
    R = cube.rotation_base
    assert np.linalg.det(R) == pytest.approx(1.0) and R[2, 2] > 0.999
    # yaw is right modulo the cube's 90° symmetry
    yaw_err = (np.arctan2(R[1, 0], R[0, 0]) - scene.cubes[0].yaw) % (np.pi / 2)
    assert min(yaw_err, np.pi / 2 - yaw_err) < np.deg2rad(2)


@pytest.mark.parametrize("colour", ALL_COLOURS)
def test_colour_classification_of_shaded_faces(colour):
    base = np.asarray(COLORS_RGB[colour], dtype=float)
    for shade in (0.55, 0.8, 1.0):  # the renderer's darkest side face to a lit top face
        assert classify_color(base * shade, black_value_max=70, min_saturation=60) == colour


def test_colour_classification_of_grey_and_odd_hues():
    assert classify_color([150, 150, 150], 70, 60) == "unknown"  # bright but unsaturated
    assert classify_color([200, 120, 20], 70, 60) == "unknown"  # orange is none of the four
    assert classify_color([20, 20, 25], 70, 60) == "black"


def test_obstacle_rule_is_configurable():
    scene = random_scene(5, cube_colors=("red",), obstacle=True)
    frame = render_scene(scene, seed=5).frame
    strict = VisionSettings(
        cubes=CubeDetectionSettings(obstacle=ObstacleRuleSettings(require="points", min_points=10**7))
    )
    result = VisionPipeline(strict).detect(frame, scene.T_base_camera)
    # Safety first: the box is not the rule's obstacle, yet it stands there, so it is still reported.
    assert [o.recognised for o in result.obstacles] == [False]
    assert any(
        "neither a cube nor the obstacle" in n and "reported as an obstacle" in n for n in result.notes
    )
    strict_only = strict.model_copy(
        update={"cubes": strict.cubes.model_copy(update={"unrecognised_as_obstacles": False})}
    )
    result = VisionPipeline(strict_only).detect(frame, scene.T_base_camera)
    assert result.obstacles == ()
    assert any("neither a cube nor the obstacle" in n for n in result.notes)
    red = VisionSettings(
        cubes=CubeDetectionSettings(obstacle=ObstacleRuleSettings(color="red", min_extent_m=0.04))
    )
    result = VisionPipeline(red).detect(frame, scene.T_base_camera)
    # the red cube now counts as the obstacle (the blue box is still one, as an unrecognised object)
    assert [o.color_label for o in result.obstacles if o.recognised] == ["red"]
    assert result.cubes == ()


def test_dbscan_parameters_come_from_settings():
    scene = random_scene(6, cube_colors=("green", "blue"))
    frame = render_scene(scene, seed=6).frame
    coarse = VisionSettings(cubes=CubeDetectionSettings(dbscan_min_points=10**6))
    result = VisionPipeline(coarse).detect(frame, scene.T_base_camera)
    assert result.cubes == ()  # no point has a million neighbours: everything is noise
    assert "no cubes detected" in result.notes


def _scene_with(boxes: list[BoxSpec], target=(0.45, 0.0)) -> SyntheticScene:
    cam = look_at_camera(np.array([target[0], target[1], 0.0]), 0.8, 55.0, 0.0)
    return SyntheticScene(T_base_camera=cam, intrinsics=d435_intrinsics(), boxes=tuple(boxes))


@pytest.mark.parametrize("colour", ["grey", "white", "black"])
def test_an_obstacle_of_any_colour_goes_into_the_planning_scene(colour):
    """Safety first: a box that is not the obstacle rule's colour is still reported as an obstacle."""
    box = BoxSpec(center=(0.42, 0.05, 0.05), size=(0.14, 0.10, 0.10), yaw=0.3, color=colour)
    scene = _scene_with([box])
    result = VisionPipeline().detect(render_scene(scene, NoiseModel(), seed=7).frame, scene.T_base_camera)
    assert result.cubes == ()
    assert len(result.obstacles) == 1, result.notes
    ob = result.obstacles[0]
    assert np.all(ob.contains(box.corners())) and not ob.recognised
    assert ob.mean_rgb is not None and ob.visibility is Visibility.WHOLE


def test_a_cube_cut_by_the_image_edge_is_no_cube_but_an_obstacle():
    """Fitted as a whole cube it lands 30-90 mm off: it is marked cut and kept out of picking."""
    case = next(c for c in map(hard_case, range(20000, 20040)) if c.cut_boxes)
    rendered = case.render()
    result = VisionPipeline().detect(rendered.frame, case.scene.T_base_camera)
    cut = case.scene.boxes[case.cut_boxes[0]]
    assert all(np.linalg.norm(c.centroid_base - np.asarray(cut.center)) > 0.05 for c in result.cubes)
    edge = [o for o in result.obstacles if o.visibility is Visibility.CUT_BY_EDGE]
    assert edge, result.notes
    assert any("cut by the image edge" in n for n in result.notes)


def test_colour_table_knows_yellow_and_unknown_colours_keep_their_mean():
    assert classify_color([215, 190, 40], 70, 60) == "yellow"
    assert classify_color([215 * 0.55, 190 * 0.55, 40 * 0.55], 70, 60) == "yellow"
    yellow = BoxSpec(center=(0.45, 0.0, 0.025), size=(0.05,) * 3, yaw=0.2, color="yellow")
    scene = _scene_with([yellow])
    frame = render_scene(scene, NoiseModel(), seed=8).frame
    result = VisionPipeline().detect(frame, scene.T_base_camera)
    assert [c.color_label for c in result.cubes] == ["yellow"]
    no_yellow = VisionSettings(
        cubes=CubeDetectionSettings(colors=tuple(c for c in DEFAULT_COLOR_TABLE if c.name != "yellow"))
    )
    result = VisionPipeline(no_yellow).detect(frame, scene.T_base_camera)
    (cube,) = result.cubes
    assert cube.color_label == "unknown"
    assert cube.mean_rgb is not None and cube.mean_rgb[0] > 100 and cube.mean_rgb[2] < 60  # still yellowish


def _occlusion_scene(occluder: BoxSpec | None) -> tuple[SyntheticScene, BoxSpec]:
    """A red cube with, optionally, a grey box between it and the camera (which looks from +x)."""
    cube = BoxSpec(center=(0.40, 0.0, 0.025), size=(0.05,) * 3, yaw=0.3, color="red")
    return _scene_with([cube] + ([occluder] if occluder else [])), cube


def test_a_partly_hidden_cube_is_fitted_from_its_visible_faces_and_marked_occluded():
    corner = BoxSpec(center=(0.47, 0.06, 0.06), size=(0.03, 0.08, 0.12), yaw=0.0, color="grey")
    scene, truth = _occlusion_scene(corner)
    result = VisionPipeline().detect(render_scene(scene, NoiseModel(), seed=1).frame, scene.T_base_camera)
    (cube,) = result.cubes
    assert cube.visibility is Visibility.OCCLUDED and 0.03 < cube.hidden_fraction < 0.3
    assert np.linalg.norm(cube.centroid_base - np.asarray(truth.center)) < 0.002
    assert len(result.obstacles) == 1  # the box in front is in the planning scene


def test_an_unoccluded_cube_is_whole():
    scene, _ = _occlusion_scene(None)
    result = VisionPipeline().detect(render_scene(scene, NoiseModel(), seed=1).frame, scene.T_base_camera)
    (cube,) = result.cubes
    assert cube.visibility is Visibility.WHOLE and cube.hidden_fraction < 0.03


def test_a_mostly_hidden_cube_is_never_reported_at_a_guessed_centre():
    wall = BoxSpec(center=(0.47, 0.0, 0.06), size=(0.03, 0.14, 0.12), yaw=0.0, color="grey")
    scene, truth = _occlusion_scene(wall)
    result = VisionPipeline().detect(render_scene(scene, NoiseModel(), seed=2).frame, scene.T_base_camera)
    assert result.cubes == ()
    assert any("hidden by something nearer" in n for n in result.notes), result.notes
    # it is still in the planning scene, as an obstacle marked occluded
    holding = [o for o in result.obstacles if np.all(o.contains(truth.corners()))]
    assert holding and holding[0].visibility is Visibility.OCCLUDED


def test_visibility_mean_colour_and_recognition_cross_the_wire():
    from pickplace.v1 import vision_pb2

    from services.vision.messages import detections_msg

    corner = BoxSpec(center=(0.47, 0.06, 0.06), size=(0.03, 0.08, 0.12), yaw=0.0, color="grey")
    scene, _ = _occlusion_scene(corner)
    result = VisionPipeline().detect(render_scene(scene, NoiseModel(), seed=1).frame, scene.T_base_camera)
    msg = vision_pb2.DetectedObjects.FromString(detections_msg(result).SerializeToString())
    (cube,) = msg.cubes
    assert cube.visibility == vision_pb2.VISIBILITY_OCCLUDED
    assert cube.hidden_fraction == pytest.approx(result.cubes[0].hidden_fraction)
    assert cube.mean_rgb.r > 100 > cube.mean_rgb.g  # red
    assert cube.fit_rms_m < 0.005
    (box,) = msg.obstacles
    assert box.visibility == vision_pb2.VISIBILITY_WHOLE and not box.recognised
    assert abs(box.mean_rgb.r - box.mean_rgb.g) < 30  # grey
