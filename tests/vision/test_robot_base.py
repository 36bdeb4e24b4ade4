"""The arm's own base stands on the table as well: it is the robot, never an obstacle in its own way."""

from __future__ import annotations

import numpy as np

from services.common.settings import VisionSettings
from services.vision.pipeline import VisionPipeline
from services.vision.synthetic import (
    BoxSpec,
    NoiseModel,
    SyntheticScene,
    d435_intrinsics,
    look_at_camera,
    render_scene,
)


def _scene() -> SyntheticScene:
    # a black "base" at the robot's origin and a grey box that really is in the way, both in view
    return SyntheticScene(
        T_base_camera=look_at_camera(np.array([0.25, 0.0, 0.0]), 0.85, 60.0),
        intrinsics=d435_intrinsics(),
        boxes=(
            BoxSpec((0.0, 0.0, 0.06), (0.15, 0.15, 0.12), 0.0, "black"),
            BoxSpec((0.42, 0.12, 0.05), (0.12, 0.10, 0.10), 0.3, "grey"),
        ),
    )


def _obstacle_centres(settings: VisionSettings) -> list[np.ndarray]:
    scene = _scene()
    result = VisionPipeline(settings).detect(
        render_scene(scene, NoiseModel(), seed=4).frame, scene.T_base_camera
    )
    return [(o.min_base + o.max_base) / 2 for o in result.obstacles if o.min_base is not None]


def test_the_robot_base_is_left_out_and_everything_else_stays_an_obstacle() -> None:
    centres = _obstacle_centres(VisionSettings())
    assert len(centres) == 1, centres
    assert np.linalg.norm(centres[0][:2] - [0.42, 0.12]) < 0.03


def test_without_the_exclusion_the_base_would_be_an_obstacle() -> None:
    # the exclusion is what keeps it out (the test above is not passing by a missed detection)
    s = VisionSettings()
    s = s.model_copy(update={"cubes": s.cubes.model_copy(update={"robot_base_radius_m": 0.0})})
    centres = _obstacle_centres(s)
    assert any(np.linalg.norm(c[:2]) < 0.05 for c in centres), centres
