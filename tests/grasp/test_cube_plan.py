"""Cube pick-and-place to colour-keyed drop zones (seed 004)."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.errors import IKFailureError, InvalidInputError
from services.common.frames import invert_transform
from services.common.modes import CubeRelease, GripperCommand
from services.common.settings import load_settings
from services.grasp.collision import MotionCollisionCheck
from services.grasp.cube import CubeObservation, drop_zone, plan_pick_and_place
from services.grasp.geometry import pose, rotation_z
from services.grasp.plan import PickPlan
from services.kinematics.analytic import fk
from services.kinematics.collision import Box
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_geometry

SETTINGS = load_settings("sim", overrides={"logging": {"file": None}})
CFG = SETTINGS.grasp
STROKE = SETTINGS.gripper.stroke_m
SPEC = get_robot("nova5")
T_FLANGE_TOOL = tool_geometry(SETTINGS).T_flange_tool()
HOME = np.radians(CFG.safe_home_joints_deg["nova5"])
SIZE = 0.05


def make_cube(color: str, seed: int) -> CubeObservation:
    rng = np.random.default_rng(seed)
    x, y, yaw = rng.uniform(0.38, 0.58), rng.uniform(-0.2, 0.2), rng.uniform(-np.pi, np.pi)
    return CubeObservation.create(pose(rotation_z(yaw), [x, y, SIZE / 2]), SIZE, color)


def plan(cube: CubeObservation, **kw: object) -> PickPlan:
    return plan_pick_and_place(SPEC, cube, HOME, CFG, T_FLANGE_TOOL, STROKE, q_home=HOME, **kw)  # type: ignore[arg-type]


@pytest.mark.parametrize(("color", "seed"), [("red", 1), ("blue", 2), ("green", 3), ("black", 4)])
def test_each_colour_goes_to_its_drop_zone(color: str, seed: int) -> None:
    cube = make_cube(color, seed)
    p = plan(cube)
    zone = np.asarray(CFG.cubes.drop_zones_m[color])
    assert np.allclose(drop_zone(CFG, color), zone)
    assert np.allclose(p.place_position[:2], zone)
    T_tool_cube = invert_transform(p.waypoint("GRASP").T_base_tool) @ cube.T_base_cube
    placed = p.waypoint("PLACE").T_base_tool @ T_tool_cube
    assert np.allclose(placed[:2, 3], zone, atol=1e-9)  # centred over the zone
    # dropped (the default): let go above the highest table, with no guarded touch-down before it
    assert CFG.cubes.release is CubeRelease.DROP
    assert placed[2, 3] - SIZE / 2 == pytest.approx(CFG.table_z_m + CFG.cubes.drop_clearance_m)
    assert not any(w.guarded for w in p.waypoints)
    assert placed[:3, 2] @ np.array([0.0, 0.0, 1.0]) > 1 - 1e-9  # set down upright
    assert p.names() == [
        "SAFE_HOME",
        "PRE_GRASP",
        "GRASP",
        "LIFT",
        "TRANSPORT",
        "PLACE_ABOVE",
        "PLACE",
        "RELEASE",
        "RETRACT",
    ]
    assert [(w.name, w.gripper) for w in p.waypoints if w.gripper] == [
        ("PRE_GRASP", GripperCommand.OPEN),
        ("GRASP", GripperCommand.CLOSE),
        ("RELEASE", GripperCommand.OPEN),
    ]
    assert p.waypoint("LIFT").T_base_tool[2, 3] >= CFG.cubes.transport_height_m
    for w in p.waypoints:
        assert SPEC.within_limits(w.q)
        assert np.allclose(fk(SPEC, w.q) @ T_FLANGE_TOOL, w.T_base_tool, atol=1e-6), w.name


def test_a_touch_down_sets_the_cube_down_guarded_and_lets_go_just_above_the_table() -> None:
    cfg = CFG.model_copy(update={"cubes": CFG.cubes.model_copy(update={"release": CubeRelease.TOUCH_DOWN})})
    cube = make_cube("blue", 2)
    p = plan_pick_and_place(SPEC, cube, HOME, cfg, T_FLANGE_TOOL, STROKE, q_home=HOME)
    dropped = plan(cube)
    T_tool_cube = invert_transform(p.waypoint("GRASP").T_base_tool) @ cube.T_base_cube
    placed = p.waypoint("PLACE").T_base_tool @ T_tool_cube
    assert placed[2, 3] - SIZE / 2 == pytest.approx(CFG.table_z_m + CFG.cubes.place_clearance_m)
    guard = p.waypoint("PLACE").guard
    assert guard is not None and guard.force_drop_n == CFG.cubes.touch_force_drop_n
    assert guard.overtravel_m == pytest.approx(CFG.cubes.guard_overtravel_m + CFG.cubes.place_clearance_m)
    assert [w.name for w in p.waypoints if w.guarded] == ["PLACE"]
    # the same grasp and turn either way; only the height the jaws open at differs
    assert np.allclose(p.waypoint("GRASP").q, dropped.waypoint("GRASP").q)
    rise = dropped.waypoint("PLACE").T_base_tool[:3, 3] - p.waypoint("PLACE").T_base_tool[:3, 3]
    assert np.allclose(rise, [0.0, 0.0, CFG.cubes.drop_clearance_m - CFG.cubes.place_clearance_m], atol=1e-9)
    for w in (*p.waypoints, *dropped.waypoints):
        assert np.allclose(fk(SPEC, w.q) @ T_FLANGE_TOOL, w.T_base_tool, atol=1e-6), w.name


def test_cube_grasp_is_top_down_across_two_faces() -> None:
    cube = make_cube("red", 9)
    g = plan(cube).grasp
    assert g.approach_direction @ np.array([0.0, 0.0, -1.0]) > 1 - 1e-9
    closing = g.T_base_tool[:3, 1]
    faces = cube.T_base_cube[:3, :2]
    assert np.max(np.abs(faces.T @ closing)) == pytest.approx(1.0)  # along a face normal
    assert np.allclose(g.T_base_tool[:2, 3], cube.T_base_cube[:2, 3], atol=1e-9)
    assert g.force_closure and g.epsilon > 0 and g.width_m == pytest.approx(SIZE)


def test_plan_over_the_obstacle_is_collision_free() -> None:
    sc = SETTINGS.sim.twin.scene
    c, h = np.array(sc.obstacle_center_m), np.array(sc.obstacle_half_size_m)
    check = MotionCollisionCheck.from_settings(SETTINGS, [Box(tuple(c - h), tuple(c + h), "wall")])
    p = plan(make_cube("blue", 5), collision_check=check)  # the wall stands before the blue zone
    for w in p.waypoints:
        held = p.held if w.holding else None
        assert not check(w.q, held), f"{w.name}: {check.explain(w.q, held)}"


def test_unknown_colour_is_rejected_naming_the_zones() -> None:
    with pytest.raises(InvalidInputError, match=r"purple.*black.*blue.*green.*red"):
        plan(make_cube("purple", 1))


def test_cube_out_of_reach_raises_ik_failure() -> None:
    cube = CubeObservation.create(pose(np.eye(3), [1.4, 0.0, SIZE / 2]), SIZE, "red")
    with pytest.raises(IKFailureError, match="reach"):
        plan(cube)


def test_malformed_cube_raises_invalid_input() -> None:
    T = np.eye(4)
    T[1, 3] = np.nan
    with pytest.raises(InvalidInputError, match="NaN"):
        CubeObservation.create(T, SIZE, "red")
    with pytest.raises(InvalidInputError, match="size"):
        CubeObservation.create(np.eye(4), -0.05, "red")


def test_alternative_takes_the_next_feasible_grasp_or_turn() -> None:
    cube = make_cube("green", 6)
    first, second = plan(cube), plan(cube, alternative=1)
    assert np.allclose(first.place_position, second.place_position)
    assert not (
        np.allclose(first.waypoint("GRASP").q, second.waypoint("GRASP").q)
        and np.allclose(first.waypoint("PLACE").q, second.waypoint("PLACE").q)
    )
    assert second.notes["joint_motion_rad"] >= first.notes["joint_motion_rad"] - 1e-9 or (
        second.grasp.quality < first.grasp.quality
    )


# the twin's obstacle, before the red and blue zones
WALL = Box((0.30, 0.315, 0.0), (0.50, 0.365, 0.12), name="wall")


def test_the_cube_is_carried_low_and_over_a_seen_box_under_its_way() -> None:
    """The lift goes only as high as the wall under the way to the blue zone asks (its top + clearance +
    the cube hanging below the tool tip); with no box there, or with the wall off the way to the green
    zone, it stays at the configured least height."""
    cc = CFG.cubes
    blue, green = make_cube("blue", 5), make_cube("green", 5)
    hang = SIZE / 2  # the tip at the cube's centre: its bottom half hangs below
    bare = plan(blue).waypoint("LIFT").T_base_tool[2, 3]
    assert bare == pytest.approx(max(cc.transport_height_m, SIZE / 2 + CFG.lift_m))
    over = plan(blue, seen_boxes=[WALL]).waypoint("LIFT").T_base_tool[2, 3]
    assert over == pytest.approx(WALL.max[2] + cc.carry_clearance_m + hang, abs=1e-6)
    assert over > bare
    assert plan(green, seen_boxes=[WALL]).waypoint("LIFT").T_base_tool[2, 3] == pytest.approx(bare)
    # carried at that height, the cube's bottom clears the wall's top by the clearance
    p = plan(blue, seen_boxes=[WALL])
    T_tool_cube = invert_transform(p.waypoint("GRASP").T_base_tool) @ blue.T_base_cube
    carried = p.waypoint("TRANSPORT").T_base_tool @ T_tool_cube
    assert carried[2, 3] - SIZE / 2 == pytest.approx(WALL.max[2] + cc.carry_clearance_m, abs=1e-6)
