"""The camera model against the arm: projection, polygon overlap, and the Nova5 in and out of view."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.errors import InvalidInputError
from services.common.settings import Settings
from services.kinematics import analytic
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_frame
from services.task.runner import view_check
from services.task.view import CameraModel, convex_hull, convex_overlap

CAM = CameraModel.look_at((0.93, 0.0, 0.66), (0.475, 0.0, 0.0), 42.5, 640, 480)


def test_the_look_at_point_projects_to_the_image_centre_and_base_y_is_image_right() -> None:
    uv, depth = CAM.project(np.array([[0.475, 0.0, 0.0], [0.475, -0.1, 0.0]]))
    assert np.allclose(uv[0], [320, 240]) and depth[0] > 0
    assert uv[1, 0] < 320  # base -y is left in the image (the camera looks back at the base)
    # the optical frame of config/calibration-sim.yaml: x along base +y, z toward the table
    assert np.allclose(CAM.T_base_camera[:3, 0], [0, 1, 0], atol=1e-9)
    assert np.allclose(CAM.T_base_camera[:3, 2], [-0.5678, 0, -0.8231], atol=1e-3)


def test_a_camera_without_a_direction_is_refused() -> None:
    with pytest.raises(InvalidInputError, match="differ"):
        CameraModel.look_at((0.5, 0, 0.5), (0.5, 0, 0.5), 40, 640, 480)


def test_convex_polygons_overlap_only_when_no_axis_separates_them() -> None:
    sq = convex_hull(np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]]))
    assert len(sq) == 4  # the inner point is not on the hull
    assert convex_overlap(sq, sq + 0.5)
    assert not convex_overlap(sq, sq + [1.5, 0])
    assert convex_overlap(sq, sq + [1.5, 0], margin=0.6)  # within the margin counts
    tri = np.array([[2.0, 0.0], [3.0, 0.0], [2.0, 1.0]])
    assert not convex_overlap(tri, sq + [2.6, 0.6])  # separated along the triangle's hypotenuse


def _tool_down_at(q_seed: np.ndarray, p: tuple[float, float, float]) -> np.ndarray:
    spec = get_robot("nova5")
    T_ft = tool_frame(Settings())
    T = analytic.fk(spec, q_seed, T_ft)
    T[:3, 3] = p
    return analytic.solve_nearest(spec, T @ np.linalg.inv(T_ft), q_seed)


def test_the_safe_home_leaves_the_view_clear_and_a_grasp_in_the_pick_zone_does_not() -> None:
    view = view_check(Settings())
    assert view is not None
    home = np.radians([180.0, 0.0, 90.0, 0.0, -90.0, 0.0])
    assert view.clear(home)
    over_zone = _tool_down_at(home, (0.47, 0.0, 0.05))
    blocking = view.blocking(over_zone)
    assert "gripper_1" in blocking and not view.clear(over_zone)


def test_clear_answers_as_the_full_list_of_blocking_pieces_does() -> None:
    """clear stops at the first blocking piece (tool first): the same answer as blocking's full list,
    on the joint line from a pose over the pick zone to the safe home that a parking search walks."""
    view = view_check(Settings())
    assert view is not None
    home = np.radians([180.0, 0.0, 90.0, 0.0, -90.0, 0.0])
    answers = []
    for p in ((0.47, 0.0, 0.05), (0.35, 0.2, 0.25), (0.5, -0.25, 0.4)):
        start = _tool_down_at(home, p)
        for s in np.linspace(0.0, 1.0, 21):
            q = start + s * (home - start)
            answers.append(view.clear(q))
            assert answers[-1] == (not view.blocking(q))
    assert any(answers) and not all(answers)


def test_a_box_around_the_arm_is_the_arm_and_a_box_elsewhere_is_not() -> None:
    view = view_check(Settings())
    assert view is not None
    q = _tool_down_at(np.radians([180.0, 0.0, 90.0, 0.0, -90.0, 0.0]), (0.45, 0.0, 0.25))
    assert view.holds_arm(q, np.array([0.40, -0.05, 0.0]), np.array([0.50, 0.05, 0.30]))
    assert not view.holds_arm(q, np.array([0.55, 0.20, 0.0]), np.array([0.60, 0.25, 0.05]))


def test_the_column_vision_stood_under_the_elbow_at_the_safe_home_is_the_arm() -> None:
    """Seed 1706: under a camera a few tenths of a degree off, the top image rows caught the elbow of the
    arm at the safe home; vision stood it on the table as a 0.39 m column beside the rod."""
    view = view_check(Settings())
    assert view is not None
    home = np.radians([180.0, 0.0, 90.0, 0.0, -90.0, 0.0])
    assert view.clear(home)  # the pick zone's view is clear; only the image edge sees the elbow
    assert view.holds_arm(home, np.array([0.501, 0.116, -0.017]), np.array([0.527, 0.154, 0.387]))
    # the real boxes of that scene (the tall blue obstacle, a cube) are not the arm
    assert not view.holds_arm(home, np.array([0.281, 0.296, -0.02]), np.array([0.52, 0.38, 0.135]))
    assert not view.holds_arm(home, np.array([0.366, -0.143, -0.01]), np.array([0.42, -0.09, 0.052]))


def test_the_camera_model_can_be_turned_off() -> None:
    s = Settings()
    assert (
        view_check(s.model_copy(update={"task": s.task.model_copy(update={"park_out_of_view": False})}))
        is None
    )
