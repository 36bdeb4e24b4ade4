"""Collision model: self-collision, table, boxes (with seed 004's y-extension), attached object."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.common.errors import InvalidInputError
from services.kinematics.collision import (
    AttachedObject,
    Box,
    CollisionChecker,
    Scene,
    _bisection_order,
    scene_from_boxes,
)
from services.kinematics.model import Kinematics, load_arm

HOME = np.deg2rad([0, 0, 90, 0, -90, 0])


@pytest.fixture(scope="module")
def arm():
    return load_arm("nova5")


def test_zero_and_home_are_free_and_adjacent_links_are_not_pairs(arm):
    cc = CollisionChecker(arm, Scene())
    assert not cc.in_collision(np.zeros(6))
    assert not cc.in_collision(HOME)
    names = {
        tuple(
            sorted(
                (
                    cc.geom.geometryObjects[p.first].name.rsplit("_", 1)[0],
                    cc.geom.geometryObjects[p.second].name.rsplit("_", 1)[0],
                )
            )
        )
        for p in cc.geom.collisionPairs
    }
    assert ("Link1", "Link2") not in names and ("Link5", "Link6") not in names
    assert ("Link2", "Link4") in names  # non-adjacent links are checked


def test_upper_arm_into_the_base_is_a_self_collision(arm):
    cc = CollisionChecker(arm, Scene(table_z=None))
    q = np.deg2rad([0, 150, 0, 0, 0, 0])  # shoulder pitched so far that the upper arm points down
    assert cc.contacts(q) == [("base_link", "Link2")]
    # the elbow folded to its limit is tight but clear (the Nova5 allows ±159.9°)
    assert not cc.in_collision(np.deg2rad([0, 0, 159, 0, 0, 0]))


def test_table_plane(arm):
    kin = Kinematics(arm)
    cc = CollisionChecker(arm, Scene(table_z=0.0))
    # tool pointing down, tip 5 cm above the table: the jaw tips are left out, so this is free
    q_low = kin.solve_ik(
        np.array([[1, 0, 0, 0.45], [0, -1, 0, 0], [0, 0, -1, 0.05], [0, 0, 0, 1.0]]),
        np.deg2rad([160, 20, 130, -60, -90, 0]),
    ).q
    assert not cc.in_collision(q_low)
    # shoulder tipped forward so far that the upper arm goes into the table
    q_dive = np.deg2rad([0, 120, 0, 0, 0, 0])
    assert ("Link3", "table") in cc.contacts(q_dive) or ("Link2", "table") in cc.contacts(q_dive)
    # the same with the table 0.2 m lower is clear of it
    assert all("table" not in p for p in CollisionChecker(arm, Scene(table_z=-2.0)).contacts(q_dive))


def test_boxes_padding_and_y_extension(arm):
    kin = Kinematics(arm)
    q = np.deg2rad([160, 20, 130, -60, -90, 0])
    tip = kin.fk(q)[:3, 3]
    box = Box(tuple(tip + [-0.05, 0.15, -0.05]), tuple(tip + [0.05, 0.25, 0.05]), "crate")
    assert not CollisionChecker(arm, Scene(boxes=(box,), table_z=None)).in_collision(q)
    # seed 004: stretched 0.5 m along ±y it reaches the tool
    stretched = CollisionChecker(arm, Scene(boxes=(box,), table_z=None, box_y_extension_m=0.5))
    assert ("crate", "gripper") in [tuple(sorted(p)) for p in stretched.contacts(q)]
    # padding: a box 2 cm from the fingers collides with 3 cm padding, not with 1 cm
    near = Box(tuple(tip + [-0.05, 0.08, -0.05]), tuple(tip + [0.05, 0.2, 0.05]), "near")
    d = CollisionChecker(arm, Scene(boxes=(near,), table_z=None)).min_distance(q)
    assert 0 < d < 0.08
    assert CollisionChecker(arm, Scene(boxes=(near,), table_z=None, padding_m=d + 0.005)).in_collision(q)
    assert not CollisionChecker(
        arm, Scene(boxes=(near,), table_z=None, padding_m=max(d - 0.005, 0))
    ).in_collision(q)


def test_attached_rod_collides_with_the_arm_and_the_world(arm):
    kin = Kinematics(arm)
    q = np.deg2rad([160, 20, 130, -60, -90, 0])
    tip = kin.fk(q)[:3, 3]
    # a rod held across the jaws (object z along the tool x axis)
    across = ((0.0, 0.0, 1.0, 0.0), (0.0, 1.0, 0.0, 0.0), (-1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    rod = AttachedObject(radius=0.011, length=0.2, T_tool_object=across)
    # a box just beside the tip (7 cm off along the rod's axis) is hit by the rod only
    R = kin.fk(q)[:3, :3]
    side = tip + R @ [0.07, 0, 0]
    box = Box(tuple(side - 0.01), tuple(side + 0.01), "peg")
    assert not CollisionChecker(arm, Scene(boxes=(box,), table_z=None)).in_collision(q)
    with_rod = CollisionChecker(arm, Scene(boxes=(box,), table_z=None, attached=rod))
    assert ("attached", "peg") in [tuple(sorted(p)) for p in with_rod.contacts(q)]
    # allowing the pair removes it
    allowed = CollisionChecker(
        arm, Scene(boxes=(box,), table_z=None, attached=rod, allowed=frozenset({("peg", "attached")}))
    )
    assert not allowed.in_collision(q)
    # the rod never counts as colliding with the gripper holding it
    assert all("gripper" not in p for p in with_rod.contacts(q))


def test_trajectory_and_path_checks_find_the_first_hit(arm):
    kin = Kinematics(arm)
    q_a = np.deg2rad([162.5, 22.6, 129.3, -61.9, -90.0, -107.5])
    q_b = q_a + np.deg2rad([70, 0, 0, 0, 0, 0])
    wall = Box((0.25, 0.20, 0.0), (0.60, 0.26, 0.25), "wall")
    cc = CollisionChecker(arm, Scene(boxes=(wall,)))
    assert not cc.in_collision(q_a) and not cc.in_collision(q_b)
    assert not cc.segment_free(q_a, q_b, math.radians(1))
    k, q_hit = cc.first_collision_on_path(np.vstack([q_a, q_b]), math.radians(1))
    assert k == 0 and cc.in_collision(q_hit)
    assert "wall" in cc.explain(q_hit)
    # the tool at the hit is next to the wall
    tip = kin.fk(q_hit)[:3, 3]
    assert 0.1 < tip[1] < 0.4
    assert cc.first_collision_on_path(np.vstack([q_a, q_a - 0.3 * (q_b - q_a)]), math.radians(1)) is None


def test_bisection_order_covers_every_index_once():
    for n in (1, 2, 3, 7, 16, 33):
        order = _bisection_order(n)
        assert sorted(order) == list(range(n + 1))
        assert order[:2] == (n, 0)
        if n >= 4:
            assert abs(order[2] - n / 2) <= 1  # the midpoint comes next


def test_bad_scene_input_is_rejected():
    with pytest.raises(InvalidInputError, match="max"):
        Box((0, 0, 0), (0, 1, 1))
    with pytest.raises(InvalidInputError, match="finite"):
        Box((0, 0, np.nan), (1, 1, 1))
    with pytest.raises(InvalidInputError, match="reserved"):
        Box((0, 0, 0), (1, 1, 1), "table")
    with pytest.raises(InvalidInputError, match="unique"):
        Scene(boxes=(Box((0, 0, 0), (1, 1, 1), "a"), Box((0, 0, 0), (1, 1, 1), "a")))
    with pytest.raises(InvalidInputError, match="padding"):
        Scene(padding_m=-0.1)
    with pytest.raises(InvalidInputError, match="shape"):
        AttachedObject(shape="sphere")
    with pytest.raises(InvalidInputError, match="positive"):
        AttachedObject(radius=0.0)
    with pytest.raises(InvalidInputError, match="6 bounds"):
        scene_from_boxes([(0, 1, 0, 1, 0)])
    scene = scene_from_boxes([(0.3, 0.5, -0.1, 0.1, 0.0, 0.2)])
    assert scene.boxes[0].min == (0.3, -0.1, 0.0) and scene.boxes[0].name == "box0"
