"""Rod pick-and-stand planner (seed 001 §3.5): geometry, reachability, one IK branch, errors."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from services.common.errors import CollisionError, IKFailureError, InvalidInputError, PlanningError
from services.common.frames import invert_transform
from services.common.modes import GripperCommand, MotionKind
from services.common.settings import GraspSettings, load_settings
from services.grasp.collision import MotionCollisionCheck
from services.grasp.geometry import pose
from services.grasp.plan import PickPlan
from services.grasp.rod import RodObservation, plan_pick_and_stand
from services.kinematics.analytic import fk
from services.kinematics.cartesian import cartesian_path
from services.kinematics.collision import Box
from services.kinematics.model import Kinematics, load_arm
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_geometry

SETTINGS = load_settings("sim", overrides={"logging": {"file": None}})
CFG = SETTINGS.grasp
STROKE = SETTINGS.gripper.stroke_m
SPEC = get_robot("nova5")
T_FLANGE_TOOL = tool_geometry(SETTINGS).T_flange_tool()
HOME = np.radians(CFG.safe_home_joints_deg["nova5"])
L, D = 0.200, 0.022
NAMES = [
    "SAFE_HOME",
    "PRE_GRASP",
    "GRASP",
    "LIFT",
    "REORIENT",
    "CARRY",
    "PLACE_ABOVE",
    "PLACE",
    "RELEASE",
    "RETRACT",
    "RETRACT_UP",
]


def random_rods(n: int, seed: int) -> list[RodObservation]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        x, y = rng.uniform(0.35, 0.60), rng.uniform(-0.25, 0.25)
        yaw = rng.uniform(-np.pi, np.pi)
        out.append(RodObservation.create([x, y, D / 2], [np.cos(yaw), np.sin(yaw), 0.0], L, D))
    return out


def plan(rod: RodObservation, cfg: GraspSettings = CFG, **kw: object) -> PickPlan:
    return plan_pick_and_stand(SPEC, rod, HOME, cfg, T_FLANGE_TOOL, STROKE, q_home=HOME, **kw)  # type: ignore[arg-type]


def T_base_rod(rod: RodObservation) -> np.ndarray:
    """The rod lying on the table: z along its (levelled) axis."""
    a = rod.axis.copy()
    a[2] = 0.0
    a /= np.linalg.norm(a)
    side = np.cross([0.0, 0.0, 1.0], a)
    return pose(np.column_stack([np.cross(side, a), side, a]), [rod.center[0], rod.center[1], D / 2])


def rod_lowest_z(T_base_rod_: np.ndarray, length: float) -> float:
    """Lowest point of the rod, from points sampled on both end rims (independent of the planner)."""
    ang = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    rim = np.column_stack([D / 2 * np.cos(ang), D / 2 * np.sin(ang), np.zeros_like(ang)])
    pts = np.vstack([rim + [0, 0, length / 2], rim - [0, 0, length / 2]])
    return float((T_base_rod_[:3, :3] @ pts.T + T_base_rod_[:3, 3:4])[2].min())


@pytest.fixture(scope="module")
def plans() -> list[tuple[RodObservation, PickPlan]]:
    return [(rod, plan(rod)) for rod in random_rods(6, seed=11)]


def test_plan_has_the_seed_001_waypoints_and_gripper_commands(plans) -> None:  # type: ignore[no-untyped-def]
    for _, p in plans:
        assert p.names() == NAMES
        actions = [(w.name, w.gripper) for w in p.waypoints if w.gripper]
        assert actions == [
            ("PRE_GRASP", GripperCommand.OPEN),
            ("GRASP", GripperCommand.CLOSE),
            ("RELEASE", GripperCommand.OPEN),
        ]
        assert all(type(w.gripper) is GripperCommand for w in p.waypoints if w.gripper)
        motions = {w.name: w.motion for w in p.waypoints}
        assert motions["SAFE_HOME"] is motions["PRE_GRASP"] is MotionKind.JOINT
        assert all(
            motions[n] is MotionKind.LINEAR
            for n in ("GRASP", "LIFT", "REORIENT", "CARRY", "PLACE_ABOVE", "PLACE", "RETRACT")
        )
        assert motions["RELEASE"] is MotionKind.HOLD  # open at touch height, do not push down
        guarded = [w.name for w in p.waypoints if w.guarded]
        assert guarded == ["PLACE"]
        assert p.waypoint("PLACE").guard.force_drop_n == pytest.approx(0.6)  # type: ignore[union-attr]


def test_every_waypoint_is_reachable_within_limits(plans) -> None:  # type: ignore[no-untyped-def]
    for _, p in plans:
        for w in p.waypoints:
            assert SPEC.within_limits(w.q), w.name
            assert np.allclose(fk(SPEC, w.q) @ T_FLANGE_TOOL, w.T_base_tool, atol=1e-6), w.name


def test_consecutive_linear_waypoints_stay_in_one_ik_branch(plans) -> None:  # type: ignore[no-untyped-def]
    """The motion package's own Cartesian interpolation (nearest-solution IK, 10° jump guard) from
    each waypoint's joints must arrive at the next waypoint's joints."""
    kin = Kinematics(load_arm("nova5", tool_geometry(SETTINGS)))
    for _, p in plans[:3]:
        wps = p.waypoints
        for prev, nxt in itertools.pairwise(wps[1:]):
            if nxt.motion is not MotionKind.LINEAR:
                continue
            path = cartesian_path(kin, prev.q, [nxt.T_base_tool], step_m=0.005, step_rad=math.radians(2.0))
            assert np.allclose(path[-1], nxt.q, atol=1e-4), f"{prev.name} → {nxt.name} changes IK branch"


def test_grasp_is_top_down_with_the_jaws_across_the_rod_at_its_centre(plans) -> None:  # type: ignore[no-untyped-def]
    for rod, p in plans:
        T = p.waypoint("GRASP").T_base_tool
        assert T[:3, 2] @ np.array([0.0, 0.0, -1.0]) > 1 - 1e-9  # approach straight down
        assert abs(T[:3, 1] @ rod.axis) < 1e-9  # jaw (closing direction) ⟂ rod axis
        assert np.linalg.norm(T[:2, 3] - rod.center[:2]) < 1e-9
        assert D / 2 - 1e-9 <= T[2, 3] <= D / 2 + CFG.gripper.pad_height_m / 2  # pads cover the axis
        assert p.grasp.force_closure and p.grasp.epsilon > 0
        assert p.waypoint("PRE_GRASP").T_base_tool[2, 3] == pytest.approx(T[2, 3] + CFG.approach_distance_m)


def test_after_reorient_the_carried_rod_is_vertical(plans) -> None:  # type: ignore[no-untyped-def]
    for rod, p in plans:
        T_tool_rod = invert_transform(p.waypoint("GRASP").T_base_tool) @ T_base_rod(rod)
        axis = (p.waypoint("REORIENT").T_base_tool @ T_tool_rod)[:3, 2]
        tilt = math.degrees(math.acos(min(1.0, abs(axis[2]))))
        assert tilt < 1.0


def test_the_rod_end_clears_the_table_along_the_dense_reorientation(plans) -> None:  # type: ignore[no-untyped-def]
    for rod, p in plans:
        T_tool_rod = invert_transform(p.waypoint("GRASP").T_base_tool) @ T_base_rod(rod)
        T0, T1 = p.waypoint("LIFT").T_base_tool, p.waypoint("REORIENT").T_base_tool
        slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]])))
        lowest = math.inf
        for s in np.linspace(0.0, 1.0, 361):
            T = pose(slerp([s]).as_matrix()[0], (1 - s) * T0[:3, 3] + s * T1[:3, 3])
            lowest = min(lowest, rod_lowest_z(T @ T_tool_rod, L))
        assert lowest >= CFG.table_z_m + 0.01, f"rod end {lowest * 1000:.1f} mm above the table"
        assert p.notes["lift_m"] >= 0.15  # the notes: 0.10 m strikes the table, 0.15 m clears


def test_place_stands_the_rod_base_on_the_table_at_the_place_position(plans) -> None:  # type: ignore[no-untyped-def]
    px, py = CFG.rod.place_xy_m  # type: ignore[misc]
    for rod, p in plans:
        T_tool_rod = invert_transform(p.waypoint("GRASP").T_base_tool) @ T_base_rod(rod)
        T_rod = p.waypoint("PLACE").T_base_tool @ T_tool_rod
        ends = [T_rod[:3, 3] + k * L / 2 * T_rod[:3, 2] for k in (1, -1)]
        base = min(ends, key=lambda e: e[2])
        assert np.allclose(base, [px, py, CFG.table_z_m], atol=1e-6)
        assert np.allclose(p.place_position, [px, py, CFG.table_z_m])
        above = p.waypoint("PLACE_ABOVE").T_base_tool
        assert above[2, 3] - p.waypoint("PLACE").T_base_tool[2, 3] == pytest.approx(CFG.rod.place_approach_m)
        assert np.array_equal(p.waypoint("RELEASE").T_base_tool, p.waypoint("PLACE").T_base_tool)
        # retract backs the open fingers off the standing rod along the approach, then rises
        back = p.waypoint("RETRACT").T_base_tool[:3, 3] - p.waypoint("PLACE").T_base_tool[:3, 3]
        assert np.allclose(back, -CFG.rod.retreat_m * p.waypoint("PLACE").T_base_tool[:3, 2])
        # ... until the tool tip clears the standing rod's top: the joint move home starts there
        assert (
            p.waypoint("RETRACT_UP").T_base_tool[2, 3] >= CFG.table_z_m + L + CFG.rod.retract_clear_m - 1e-9
        )


def test_an_off_centre_grasp_still_retracts_above_the_standing_rod() -> None:
    # grasped 5.5 cm off centre, the tool stands low on the rod at PLACE: the rise must cover it
    cfg = CFG.model_copy(update={"rod": CFG.rod.model_copy(update={"grasp_offset_m": -0.055})})
    p = plan(random_rods(1, seed=7)[0], cfg)
    place_z = p.waypoint("PLACE").T_base_tool[2, 3]
    up_z = p.waypoint("RETRACT_UP").T_base_tool[2, 3]
    assert up_z >= CFG.table_z_m + L + CFG.rod.retract_clear_m - 1e-9
    assert up_z - place_z > CFG.rod.retract_up_m  # more than the fixed rise would give


def test_stands_the_rod_where_it_lay_without_a_place_position() -> None:
    cfg = CFG.model_copy(update={"rod": CFG.rod.model_copy(update={"place_xy_m": None})})
    rod = random_rods(1, seed=5)[0]
    p = plan(rod, cfg)
    assert np.allclose(p.place_position[:2], rod.center[:2])


def test_plan_is_collision_free_with_the_motion_checker_and_an_obstacle() -> None:
    sc = SETTINGS.sim.twin.scene
    c, h = np.array(sc.obstacle_center_m), np.array(sc.obstacle_half_size_m)
    check = MotionCollisionCheck.from_settings(SETTINGS, [Box(tuple(c - h), tuple(c + h), "wall")])
    for rod in random_rods(3, seed=23):
        p = plan(rod, collision_check=check)
        for w in p.waypoints:
            held = p.held if w.holding else None
            assert not check(w.q, held), f"{w.name}: {check.explain(w.q, held)}"


def test_a_blocked_cell_raises_a_collision_error() -> None:
    rod = random_rods(1, seed=2)[0]
    with pytest.raises(CollisionError, match=r"collision|with"):
        plan(rod, collision_check=lambda q, held: True)


def test_unreachable_rod_raises_a_planning_error_naming_why() -> None:
    rod = RodObservation.create([1.5, 0.0, D / 2], [0.0, 1.0, 0.0], L, D)
    with pytest.raises(IKFailureError, match=r"reach") as info:
        plan(rod)
    assert isinstance(info.value, PlanningError)
    assert "1.500" in str(info.value)


def test_rod_out_of_the_workspace_below_the_shoulder_reports_the_failed_stage() -> None:
    rod = RodObservation.create([0.05, 0.05, D / 2], [1.0, 0.0, 0.0], L, D)  # under the arm's base
    with pytest.raises(PlanningError, match="no feasible pick-and-stand"):
        plan(rod)


@pytest.mark.parametrize(
    ("center", "axis", "match"),
    [
        ([np.nan, 0.0, D / 2], [1.0, 0.0, 0.0], "NaN"),
        ([0.45, 0.0, D / 2], [np.inf, 0.0, 0.0], "NaN"),
        ([0.45, 0.0, D / 2], [0.0, 0.0, 0.0], "non-zero"),
        ([0.45, 0.0], [1.0, 0.0, 0.0], "3 values"),
    ],
)
def test_malformed_rod_raises_invalid_input(center: list[float], axis: list[float], match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        RodObservation.create(center, axis, L, D)


def test_standing_or_floating_rod_is_rejected() -> None:
    with pytest.raises(InvalidInputError, match="from level"):
        plan(RodObservation.create([0.45, 0.0, 0.1], [0.0, 0.3, 1.0], L, D))
    with pytest.raises(InvalidInputError, match="not on the table"):
        plan(RodObservation.create([0.45, 0.0, 0.2], [1.0, 0.0, 0.0], L, D))
    with pytest.raises(InvalidInputError, match="current joints"):
        plan_pick_and_stand(SPEC, random_rods(1, 1)[0], [np.nan] * 6, CFG, T_FLANGE_TOOL, STROKE)


def test_other_robot_models_plan_too() -> None:
    spec = get_robot("ur5e")
    home = np.radians(CFG.safe_home_joints_deg["ur5e"])
    rod = RodObservation.create([0.45, 0.05, D / 2], [0.6, 0.8, 0.0], L, D)
    p = plan_pick_and_stand(spec, rod, home, CFG, T_FLANGE_TOOL, STROKE, q_home=home)
    for w in p.waypoints:
        assert np.allclose(fk(spec, w.q) @ T_FLANGE_TOOL, w.T_base_tool, atol=1e-6)


def test_alternatives_are_other_feasible_wrist_options_in_cost_order() -> None:
    rod = random_rods(1, seed=4)[0]
    first, second = plan(rod), plan(rod, alternative=1)
    assert second.notes["joint_motion_rad"] >= first.notes["joint_motion_rad"]
    assert not np.allclose(first.waypoint("REORIENT").q, second.waypoint("REORIENT").q)
    with pytest.raises(PlanningError, match="alternative 500"):
        plan(rod, alternative=500)


@pytest.mark.parametrize("seen_above_mm", [0.0, 4.0, 7.0, 9.0])
def test_a_rod_seen_above_the_configured_table_is_gripped_at_its_axis(seen_above_mm: float) -> None:
    """A table a few mm higher than configured (and a camera that sees it so) puts the rod's axis that
    much higher: the pads grip it there, the fingertips still clear the seen table (issue 19's eval
    refused 34 of 1,000 such rods at PLAN while the axis was taken at the configured table)."""
    dz = seen_above_mm / 1000.0
    rod = RodObservation.create([0.5, 0.1, D / 2 + dz], [0.0, 1.0, 0.0], L, D)
    g = CFG.gripper
    tcp_z = plan(rod).waypoint("GRASP").T_base_tool[2, 3]
    axis_z = CFG.table_z_m + dz + D / 2
    assert tcp_z - axis_z <= g.pad_height_m / 2 + 1e-9  # the pads reach the axis
    assert tcp_z - g.fingertip_beyond_tcp_m >= CFG.table_z_m + dz + g.table_clearance_m - 1e-9


# Randomized eval seed 1478 (table, cubes and rod as the grasp service saw them): a rod 0.54 m out
# lying along the base's y axis has no turn over the grasp that keeps the arm off the table and the
# cubes; 7 of 1,000 randomized trials were refused at PLAN like this.
FAR_ROD = RodObservation.create(
    [0.54337063758956949, 0.094738607152590637, 0.011854942279620584],
    [-0.12175453262377152, 0.99256011990540427, -0.0004920964704486062],
    0.20045413543577795,
    0.022096778087140445,
)
FAR_ROD_PLACE = [0.39343145750507624, 0.05656854249492381]
FAR_ROD_SCENE = [
    Box((0.27968, 0.29079, -0.00965), (0.50972, 0.37067, 0.13849), "obstacle0"),
    Box((0.40831, -0.19067, 0.0), (0.45831, -0.14067, 0.05074), "obstacle1"),
    Box((0.42622, 0.11445, 0.0), (0.47622, 0.16445, 0.05068), "obstacle2"),
    Box((0.44184, -0.03188, 0.0), (0.49184, 0.01812, 0.05075), "obstacle3"),
    Box((0.52279, -0.17778, 0.0), (0.57279, -0.12778, 0.05093), "obstacle4"),
]


def test_a_far_rod_along_y_is_turned_upright_nearer_the_base(monkeypatch: pytest.MonkeyPatch) -> None:
    import services.grasp.rod as rod_planner

    check = MotionCollisionCheck.from_settings(SETTINGS, FAR_ROD_SCENE)
    p = plan(FAR_ROD, collision_check=check, place_xy=FAR_ROD_PLACE)
    w = {x.name: x for x in p.waypoints}
    grasp_xy, turn_xy = w["GRASP"].T_base_tool[:2, 3], w["REORIENT"].T_base_tool[:2, 3]
    assert np.linalg.norm(turn_xy - grasp_xy) > 0.05  # turned elsewhere than over the grasp ...
    assert np.linalg.norm(turn_xy) < np.linalg.norm(grasp_xy) - 0.05  # ... and nearer the base
    for x in p.waypoints:
        held = p.held if x.holding else None
        assert not check(x.q, held), f"{x.name}: {check.explain(x.q, held)}"
    assert p.notes["min_rod_clearance_m"] >= CFG.rod.turn_clearance_m - 1e-9

    only_over_the_grasp = rod_planner._turn_sites
    monkeypatch.setattr(rod_planner, "_turn_sites", lambda g, xy, cfg: only_over_the_grasp(g, xy, cfg)[:1])
    with pytest.raises(CollisionError, match="no feasible pick-and-stand"):
        plan(FAR_ROD, collision_check=check, place_xy=FAR_ROD_PLACE)


# seed 1912 as vision saw it after seed 1911 (a wall and four cubes around the rod): the cheapest IK
# branch of every wrist option collides (the elbow on the table, a cube at the fingers), an axis 0.4°
# different planned; another branch of one option is free
SEED_1912_ROD = RodObservation.create(
    [0.50473, -0.12295, 0.01726], [0.57411, 0.81877, 0.00177], 0.2006, 0.0227
)
SEED_1912_BOXES = [
    Box((0.2826, 0.3039, -0.0014), (0.512, 0.3831, 0.1519), "wall"),
    Box((0.3593, -0.1528, 0.0), (0.4093, -0.1028, 0.0568), "cube0"),
    Box((0.4105, 0.0857, 0.0), (0.4605, 0.1357, 0.0578), "cube1"),
    Box((0.4315, -0.057, 0.0), (0.4815, -0.007, 0.057), "cube2"),
    Box((0.5292, -0.2356, 0.0), (0.5792, -0.1856, 0.0556), "cube3"),
]


def test_another_ik_branch_is_taken_when_asked_and_every_cheapest_one_collides() -> None:
    check = MotionCollisionCheck.from_settings(SETTINGS, SEED_1912_BOXES)
    place = [0.37609, 0.03061]
    with pytest.raises(CollisionError, match="with table"):
        plan(SEED_1912_ROD, collision_check=check, place_xy=place)  # not asked: the cheapest only
    p = plan(SEED_1912_ROD, collision_check=check, place_xy=place, other_branches=True)
    for w in p.waypoints:
        held = p.held if w.holding else None
        assert not check(w.q, held), f"{w.name}: {check.explain(w.q, held)}"
        assert np.allclose(fk(SPEC, w.q) @ T_FLANGE_TOOL, w.T_base_tool, atol=1e-6), w.name
    steps = np.abs(np.diff([w.q for w in p.waypoints if w.name in NAMES[2:8]], axis=0))
    assert p.notes["joint_motion_rad"] >= float(steps.max(axis=1).sum()) - 1e-9  # its cost is its own


def test_a_costlier_branch_keeps_the_elbow_bent_the_way_it_is_at_home() -> None:
    """A joint move from the safe home to a branch with the elbow bent the other way straightens the arm on
    the way: the tool went 1.2 m up, past the workspace (7 of 200 randomized trials, when costlier branches
    were taken before other grasp offsets)."""
    from services.grasp.rod import _elbow_as_at

    path = np.tile(HOME, (5, 1))
    assert _elbow_as_at(HOME, path)
    path[3, 2] = -0.3
    assert not _elbow_as_at(HOME, path)
    check = MotionCollisionCheck.from_settings(SETTINGS, SEED_1912_BOXES)
    p = plan(SEED_1912_ROD, collision_check=check, place_xy=[0.37609, 0.03061], other_branches=True)
    assert all(np.sign(w.q[2]) == np.sign(HOME[2]) for w in p.waypoints)


def test_the_standing_rod_is_carried_over_a_seen_box_under_its_way_only() -> None:
    """With nothing under the way to the place, the rod comes at the height it turned at (or at the
    place approach, when higher) and goes straight down; a box under the way lifts the carry until the
    rod's lower end clears the box's top by the clearance; a box off the way changes nothing."""
    rod = RodObservation.create([0.50, 0.15, D / 2], [0.0, 1.0, 0.0], L, D)
    px, py = CFG.rod.place_xy_m  # type: ignore[misc]

    def carry_and_lower_end(p: PickPlan) -> tuple[float, float]:
        T_tool_rod = invert_transform(p.waypoint("GRASP").T_base_tool) @ T_base_rod(rod)
        T_rod = p.waypoint("CARRY").T_base_tool @ T_tool_rod
        low = min((T_rod[:3, 3] + k * L / 2 * T_rod[:3, 2] for k in (1, -1)), key=lambda e: e[2])
        return float(p.waypoint("CARRY").T_base_tool[2, 3]), float(low[2])

    bare = plan(rod)
    z_bare, _ = carry_and_lower_end(bare)
    lift, above = bare.waypoint("LIFT").T_base_tool[2, 3], bare.waypoint("PLACE_ABOVE").T_base_tool[2, 3]
    assert z_bare == pytest.approx(max(lift, above))
    # a 12 cm box just short of the place, where the rod comes from
    box = Box((px - 0.02, py + 0.06, 0.0), (px + 0.02, py + 0.10, 0.12), name="box")
    z_box, low_box = carry_and_lower_end(plan(rod, seen_boxes=[box]))
    assert low_box == pytest.approx(box.max[2] + CFG.rod.carry_clearance_m, abs=1e-6)
    assert z_box > z_bare
    far = Box((px - 0.02, -0.40, 0.0), (px + 0.02, -0.36, 0.12), name="far")  # the other side of the place
    assert carry_and_lower_end(plan(rod, seen_boxes=[far]))[0] == pytest.approx(z_bare)
