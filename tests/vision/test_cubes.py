"""Seed 004 cube/obstacle pipeline on seeded synthetic scenes: centroids, colours, obstacle boxes."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.settings import CubeDetectionSettings, ObstacleRuleSettings, VisionSettings
from services.vision.cubes import classify_color
from services.vision.pipeline import VisionPipeline
from services.vision.synthetic import COLORS_RGB, NoiseModel, render_scene
from services.vision.synthetic_scenes import random_scene

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
    assert result.obstacles == ()
    assert any("neither a cube nor the obstacle" in n for n in result.notes)
    red = VisionSettings(
        cubes=CubeDetectionSettings(obstacle=ObstacleRuleSettings(color="red", min_extent_m=0.04))
    )
    result = VisionPipeline(red).detect(frame, scene.T_base_camera)
    assert [o.color_label for o in result.obstacles] == ["red"]  # the red cube now counts as an obstacle
    assert result.cubes == ()


def test_dbscan_parameters_come_from_settings():
    scene = random_scene(6, cube_colors=("green", "blue"))
    frame = render_scene(scene, seed=6).frame
    coarse = VisionSettings(cubes=CubeDetectionSettings(dbscan_min_points=10**6))
    result = VisionPipeline(coarse).detect(frame, scene.T_base_camera)
    assert result.cubes == ()  # no point has a million neighbours: everything is noise
    assert "no cubes detected" in result.notes
