"""The stand-up carry as joint moves (services.grasp.rod_carry): where they replace the tool lines, the
rod and the arm stay as clear as the lines kept them; where they may not, the lines stay and say why."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from services.common.frames import invert_transform
from services.common.modes import MotionKind
from services.grasp.collision import MotionCollisionCheck
from services.grasp.geometry import lowest_gripper_z
from services.grasp.plan import PickPlan
from services.grasp.rod_carry import CARRY_KEYS, CarryFloors, joint_carry
from services.kinematics.analytic import fk
from services.kinematics.collision import Box
from tests.grasp.test_rod_plan import (
    CFG,
    NAMES,
    SETTINGS,
    SPEC,
    T_FLANGE_TOOL,
    L,
    T_base_rod,
    plan,
    random_rods,
    rod_lowest_z,
)

SAMPLES = 200  # per joint move, for the checks here (the planner samples every 1°)


def obstacle_check() -> MotionCollisionCheck:
    sc = SETTINGS.sim.twin.scene
    c, h = np.array(sc.obstacle_center_m), np.array(sc.obstacle_half_size_m)
    return MotionCollisionCheck.from_settings(SETTINGS, [Box(tuple(c - h), tuple(c + h), "wall")])


@pytest.fixture(scope="module")
def checked() -> list[tuple[object, PickPlan, MotionCollisionCheck]]:
    check = obstacle_check()
    return [(rod, plan(rod, collision_check=check), check) for rod in random_rods(8, seed=11)]


def carry_of(p: PickPlan) -> list[str]:
    names = p.names()
    return names[names.index("LIFT") : names.index("PLACE")]


def test_with_collision_checks_the_carry_is_joint_moves_from_the_lift_to_above_the_place(checked) -> None:  # type: ignore[no-untyped-def]
    for _rod, p, _check in checked:
        carry = carry_of(p)
        assert carry[0] == "LIFT" and carry[-1] == "PLACE_ABOVE" and "REORIENT" in carry
        assert all(p.waypoint(n).motion is MotionKind.JOINT for n in carry[1:]), carry
        assert p.waypoint("LIFT").motion is MotionKind.LINEAR  # lifted off the table straight up
        assert "CARRY" not in carry  # the upright rod went straight to above the place
        # the rest of the plan is as before
        assert [n for n in p.names() if n not in carry] == [n for n in NAMES if n not in CARRY_KEYS]
        assert p.notes["carry_to_place_above"] == "joint moves in 1 part(s)"


def test_the_joint_carry_keeps_the_rod_fingers_and_arm_clear(checked) -> None:  # type: ignore[no-untyped-def]
    """Checked here independently of the planner: the joint moves sampled densely, the rod's lowest rim
    point and the fingers over the table, and the motion checker's verdict with the rod held."""
    g = CFG.gripper
    table = CFG.table_z_m
    for rod, p, check in checked:
        T_tool_rod = invert_transform(p.waypoint("GRASP").T_base_tool) @ T_base_rod(rod)  # type: ignore[arg-type]
        wps = [p.waypoint(n) for n in carry_of(p)]
        lowest = np.inf
        for a, b in itertools.pairwise(wps):
            for s in np.linspace(0.0, 1.0, SAMPLES):
                q = a.q + s * (b.q - a.q)
                T = fk(SPEC, q) @ T_FLANGE_TOOL
                lowest = min(lowest, rod_lowest_z(T @ T_tool_rod, L))
                assert (
                    lowest_gripper_z(g, T, rod.diameter + g.width_margin_m)
                    >= table + g.table_clearance_m - 1e-6
                )  # type: ignore[attr-defined]
                assert not check(q, p.held), f"{a.name} → {b.name}: {check.explain(q, p.held)}"
        # the rod's nominal end: its lowest is above the place approach's, less what the tolerance allows
        assert lowest >= table + CFG.rod.place_approach_m - 1e-3, f"{lowest * 1000:.1f} mm"


def test_a_turn_through_the_tool_lines_joints_passes_them_where_the_line_does(checked) -> None:  # type: ignore[no-untyped-def]
    vias = [(p, n) for _r, p, _c in checked for n in carry_of(p) if n.startswith("REORIENT_")]
    assert vias, "some turn went in two parts"
    for p, n in vias:
        w = p.waypoint(n)
        assert np.allclose(fk(SPEC, w.q) @ T_FLANGE_TOOL, w.T_base_tool, atol=1e-6)  # its own pose
        # on the tool line from the lift to the turn: the tool tip turns about a fixed point there
        a, b = p.waypoint("LIFT").T_base_tool[:3, 3], p.waypoint("REORIENT").T_base_tool[:3, 3]
        x = w.T_base_tool[:3, 3]
        t = float(np.dot(x - a, b - a) / max(np.dot(b - a, b - a), 1e-12))
        assert np.linalg.norm(a + np.clip(t, 0, 1) * (b - a) - x) < 1e-6


def test_without_collision_checks_or_when_turned_off_the_carry_keeps_to_the_tool_lines() -> None:
    rod = random_rods(1, seed=11)[0]
    off = CFG.model_copy(update={"rod": CFG.rod.model_copy(update={"joint_moves": False})})
    for p, why in (
        (plan(rod), "no collision check"),
        (plan(rod, off, collision_check=obstacle_check()), "off"),
    ):
        assert p.names() == NAMES
        assert all(p.waypoint(n).motion is MotionKind.LINEAR for n in CARRY_KEYS)
        assert p.notes["carry_to_reorient"] == f"tool line: {why}"


def test_a_joint_move_that_fails_a_check_leaves_the_tool_line_with_the_reason(checked) -> None:  # type: ignore[no-untyped-def]
    _rod, p, check = checked[0]
    names = carry_of(p)
    q_path = np.stack([p.waypoint(n).q for n in names] + [p.waypoint("PLACE_ABOVE").q])
    keys = {"LIFT": 0, "REORIENT": names.index("REORIENT"), "CARRY": len(names), "PLACE_ABOVE": len(names)}
    table = CFG.table_z_m
    # a turn that must keep the rod 0.5 m above the table: no joint move does, in any number of parts
    high = joint_carry(SPEC, q_path, keys, p.held, CarryFloors(table + 0.5, table), CFG, T_FLANGE_TOOL, check)
    assert high["REORIENT"].why_line.startswith("the rod end would come within")
    assert not high["PLACE_ABOVE"].why_line  # the upright rod still goes straight
    # everything collides with the rod held: every move keeps to its line
    blocked = joint_carry(
        SPEC,
        q_path,
        keys,
        p.held,
        CarryFloors(table, table),
        CFG,
        T_FLANGE_TOOL,
        lambda q, held: held is not None,
    )
    assert {n: m.why_line for n, m in blocked.items()} == dict.fromkeys(
        CARRY_KEYS[1:], "a collision with the rod held"
    )


def standing_box(p: PickPlan, rod: object) -> Box:
    """The stood rod as the task's way home is planned past it (services.task.moves.placed_box): the
    rod's radius round the place, its length + 0.03 m high, with the rod held 30 mm off its centre."""
    x, y = p.place_position[:2]
    r = p.held.radius
    return Box((x - r, y - r, 0.0), (x + r, y + r, p.held.length + CFG.rod.offset_tolerance_m + 0.03), "rod")


def test_the_rise_after_the_retract_goes_on_the_joint_line_home_only_where_it_passes_the_standing_rod(  # type: ignore[no-untyped-def]
    checked,
) -> None:
    home = np.radians(CFG.safe_home_joints_deg["nova5"])
    kinds = {p.notes["rise_after_retract"].split(":")[0] for _r, p, _c in checked}
    assert kinds == {"joint move on the line home", "tool line"}, kinds  # both kinds in this set
    for rod, p, check in checked:
        up, back = p.waypoint("RETRACT_UP"), p.waypoint("RETRACT")
        assert np.allclose(fk(SPEC, up.q) @ T_FLANGE_TOOL, up.T_base_tool, atol=1e-6)
        if up.motion is MotionKind.LINEAR:  # straight up above the rod first, as before
            assert p.notes["rise_after_retract"].startswith("tool line: the way home from the retract meets")
            assert np.allclose(up.T_base_tool[:2, 3], back.T_base_tool[:2, 3], atol=1e-9)
            continue
        # on the straight joint line from the retract to the safe home, the tool as high as the line rose
        # above the rod (or home itself) ...
        d = (up.q - back.q) / (home - back.q)
        assert np.allclose(d, d[0], atol=1e-9) and 0.0 < d[0] <= 1.0
        top = rod.length + CFG.rod.retract_clear_m  # type: ignore[attr-defined]
        assert up.T_base_tool[2, 3] >= CFG.table_z_m + top - 1e-9 or d[0] == pytest.approx(1.0)
        # ... and the whole line home passes the standing rod, checked here with its box in the scene
        with_rod = check.with_boxes([standing_box(p, rod)])
        for s in np.linspace(0.0, 1.0, SAMPLES):
            q = back.q + s * (home - back.q)
            assert not with_rod(q, None), f"{s:.2f} of the way home: {with_rod.explain(q)}"


def test_without_collision_checks_the_rise_after_the_retract_stays_the_line_up() -> None:
    p = plan(random_rods(1, seed=11)[0])
    assert p.waypoint("RETRACT_UP").motion is MotionKind.LINEAR
    assert p.notes["rise_after_retract"] == "tool line: no collision check with the standing rod"
