"""Antipodal grasp synthesis (LLD §4.2): candidates, filters, force closure, quality, reachability."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError
from services.common.settings import GraspSettings, load_settings
from services.grasp.geometry import lowest_gripper_z, pose, rotation_z
from services.grasp.synthesis import ObjectSpec, compute_grasps, synthesize, width_quality
from services.kinematics.analytic import fk
from services.kinematics.robot_models import get_robot

SETTINGS = load_settings("sim", overrides={"logging": {"file": None}})
CFG = SETTINGS.grasp
STROKE = SETTINGS.gripper.stroke_m
SPEC = get_robot("nova5")
T_FLANGE_TOOL = pose(np.eye(3), [0.0, 0.0, SETTINGS.gripper.tcp_offset_m])
HOME = np.radians(CFG.safe_home_joints_deg["nova5"])


def lying_rod(x: float = 0.45, y: float = 0.05, yaw: float = 0.3) -> ObjectSpec:
    """A 200 × 22 mm cylinder lying on the table: object z (axis) horizontal at heading ``yaw``."""
    R = rotation_z(yaw) @ Rotation.from_euler("y", 90, degrees=True).as_matrix()
    return ObjectSpec.from_request("cylinder", pose(R, [x, y, 0.011]), 0.022, 0.022, 0.2)


def cube(x: float = 0.5, y: float = -0.1, yaw: float = 0.4, size: float = 0.05) -> ObjectSpec:
    return ObjectSpec.from_request("box", pose(rotation_z(yaw), [x, y, size / 2]), size, size, size)


def run(obj: ObjectSpec, cfg: GraspSettings = CFG, **kw: object):  # type: ignore[no-untyped-def]
    return compute_grasps(obj, SPEC, T_FLANGE_TOOL, HOME, cfg, STROKE, **kw)  # type: ignore[arg-type]


def test_lying_rod_best_grasp_is_top_down_centred_and_across_the_axis() -> None:
    obj = lying_rod()
    res = run(obj)
    assert res.grasps, res.summary()
    best = res.grasps[0]
    axis = obj.T_base_object[:3, 2]
    assert best.approach_direction @ np.array([0.0, 0.0, -1.0]) > 0.999
    assert abs(best.T_base_tool[:3, 1] @ axis) < 1e-9  # jaws close across the rod
    assert np.linalg.norm(best.T_base_tool[:2, 3] - obj.T_base_object[:2, 3]) < 1e-9  # at its centre
    assert best.force_closure and best.epsilon > 0
    # grasps off the centre rank lower
    off = [g for g in res.grasps if np.linalg.norm(g.T_base_tool[:2, 3] - obj.T_base_object[:2, 3]) > 0.01]
    assert off and all(g.quality < best.quality for g in off)


def test_grasps_are_ranked_force_closed_reachable_and_above_the_table() -> None:
    for obj in (
        lying_rod(),
        cube(),
        ObjectSpec.from_request("sphere", pose(np.eye(3), [0.5, 0.0, 0.03]), 0.06, 0, 0),
    ):
        res = run(obj)
        assert res.grasps, res.summary()
        q = [g.quality for g in res.grasps]
        assert q == sorted(q, reverse=True)
        for g in res.grasps:
            assert g.force_closure and g.epsilon > 0 and 0 <= g.quality <= 1
            assert g.approach_direction[2] <= 0.05  # never from below
            assert lowest_gripper_z(CFG.gripper, g.T_base_tool, g.opening_m) >= CFG.table_z_m
            assert g.q is not None and SPEC.within_limits(g.q)
            assert np.allclose(fk(SPEC, g.q) @ T_FLANGE_TOOL, g.T_base_tool, atol=1e-6)


def test_box_grasps_close_only_across_sides_that_fit_the_stroke() -> None:
    wide = ObjectSpec.from_request("box", pose(np.eye(3), [0.5, 0.0, 0.03]), 0.12, 0.04, 0.06)
    res = run(wide)
    assert res.grasps
    for g in res.grasps:
        closing = g.T_base_tool[:3, 1]
        assert abs(closing @ np.array([1.0, 0.0, 0.0])) < 1e-9  # never across the 120 mm side
        assert g.width_m <= STROKE
    too_big = ObjectSpec.from_request("box", pose(np.eye(3), [0.5, 0.0, 0.1]), 0.2, 0.2, 0.2)
    assert run(too_big).grasps == []


def test_cube_top_grasps_rank_above_side_grasps() -> None:
    res = run(cube(size=0.04), check_reach=False)
    tops = [g for g in res.grasps if g.approach_direction[2] < -0.99]
    sides = [g for g in res.grasps if abs(g.approach_direction[2]) < 0.01]
    assert tops
    assert not sides or max(g.quality for g in sides) < max(g.quality for g in tops)


def test_sphere_needs_soft_fingers_for_force_closure() -> None:
    ball = ObjectSpec.from_request("sphere", pose(np.eye(3), [0.5, 0.0, 0.03]), 0.06, 0, 0)
    hard = CFG.model_copy(
        update={"force_closure": CFG.force_closure.model_copy(update={"torsional_friction_m": 0.0})}
    )
    res = synthesize(ball, hard, STROKE)
    assert res.grasps == [] and res.rejected["no force closure"] > 0
    assert synthesize(ball, CFG, STROKE).grasps


def test_object_out_of_reach_has_no_grasps() -> None:
    far = cube(x=1.5, y=0.0)
    res = run(far)
    assert res.grasps == [] and res.rejected["unreachable"] > 0


def test_collision_filter_rejects_grasps() -> None:
    res = run(cube(), collision_check=lambda q, held: True)
    assert res.grasps == [] and res.rejected["collision"] > 0


def test_width_quality_is_the_lld_score() -> None:
    assert width_quality(0.0425, 0.085) == pytest.approx(1.0)
    assert width_quality(0.085, 0.085) == pytest.approx(0.75)
    assert width_quality(0.0, 0.085) == pytest.approx(0.75)
    assert width_quality(0.1, 0.085) == 0.0


@pytest.mark.parametrize(
    ("shape", "dims", "match"),
    [
        ("cone", (0.05, 0.05, 0.05), "shape"),
        ("box", (0.05, float("nan"), 0.05), "depth"),
        ("cylinder", (-0.02, 0.0, 0.1), "width"),
        ("sphere", (0.0, 0.0, 0.0), "width"),
    ],
)
def test_bad_object_requests_raise_invalid_input(
    shape: str, dims: tuple[float, float, float], match: str
) -> None:
    with pytest.raises(InvalidInputError, match=match):
        ObjectSpec.from_request(shape, np.eye(4), *dims)


def test_nan_object_pose_raises_invalid_input() -> None:
    T = np.eye(4)
    T[0, 3] = np.nan
    with pytest.raises(InvalidInputError, match="NaN"):
        ObjectSpec.from_request("box", T, 0.05, 0.05, 0.05)
