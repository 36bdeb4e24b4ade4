"""A rod grasped off its centre is measured held above the place and turned straight before the touch-down."""

from __future__ import annotations

import asyncio
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from services.common.errors import CameraConnectionError
from services.common.modes import MotionKind, TaskKind
from services.task.cycle_config import CycleConfig
from services.task.ports import SeenAxis
from services.task.recovery import RetryLimits
from services.task.straighten import held_rod_query, straightening, turn_from, turned
from tests.task.fakes import HOME, FakeCell, FakeGrasp, FakeVision, rod_at, seen

OFF_CENTRE = 0.035


def _leaning(deg: float, about: tuple[float, float, float] = (0.0, 1.0, 0.0)) -> np.ndarray:
    return Rotation.from_rotvec(np.deg2rad(deg) * np.asarray(about)).apply([0.0, 0.0, 1.0])


# ------------------------------------------------------------------ the pure parts
def test_the_query_looks_along_the_tools_x_up_above_the_table_less_the_fingers():
    T = np.eye(4)
    T[:3, :3] = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]  # tool x down: the rod hangs
    T[:3, 3] = [0.45, 0.0, 0.14]
    q = held_rod_query(T, rod_at(0.3, 0.0), OFF_CENTRE, 0.03, 0.0)
    assert np.allclose(q.direction, [0.0, 0.0, 1.0])  # up, whichever way the tool's x points
    assert np.allclose(q.point, T[:3, 3])
    assert q.along_max_m == pytest.approx(0.1 + OFF_CENTRE + 0.015)
    assert q.along_min_m == pytest.approx(0.012 - 0.14)  # not the table around its foot
    assert q.skip_min_m == pytest.approx(-q.skip_max_m) and q.skip_max_m == pytest.approx(0.015 + 0.008)
    assert q.search_radius_m == pytest.approx(0.011 + 0.015) and q.rod_diameter_m == 0.022


@pytest.mark.parametrize("deg", [0.0, 0.7, 3.0, 170.0])
def test_straightening_brings_the_axis_to_the_vertical_by_the_least_turn(deg):
    axis = _leaning(deg, (1.0, 1.0, 0.0) / np.sqrt(2))
    R = straightening(axis)
    up = R @ axis
    assert np.allclose(np.abs(up), [0.0, 0.0, 1.0], atol=1e-12)
    assert np.isclose(np.linalg.det(R), 1.0)
    turn = np.degrees(Rotation.from_matrix(R).magnitude())
    assert turn == pytest.approx(min(deg, 180.0 - deg), abs=1e-9)  # either way along the axis


def test_the_rest_of_the_plan_turns_about_the_touch_down_up_to_the_way_home():
    p = asyncio.run(FakeGrasp().plan_rod(rod_at(0.5, 0.1), HOME, (), 0))
    first = [w.name for w in p.waypoints].index("PLACE")
    before = [w.T_base_tool.copy() for w in p.waypoints]
    R = straightening(_leaning(2.0))
    done = turn_from(p, first, R)
    assert [p.waypoints[k].name for k in done] == ["PLACE", "RELEASE", "RETRACT"]
    pivot = before[first][:3, 3]
    assert np.allclose(p.waypoints[first].T_base_tool[:3, 3], pivot)  # the rod's foot lands where planned
    for k in done:
        assert np.allclose(p.waypoints[k].T_base_tool, turned(before[k], R, pivot))
    for k in range(first):
        assert np.array_equal(p.waypoints[k].T_base_tool, before[k])


# ------------------------------------------------------------------ in the cycle
def _config(from_offset: float = 0.02) -> CycleConfig:
    return CycleConfig(
        limits=RetryLimits(detect=2, grasp_variants=3, alarms=2, regrasps=1),
        home_joints=tuple(HOME),
        grasp_offsets_m=(OFF_CENTRE, 0.0),
        straighten_from_offset_m=from_offset,
    )


def _axis(deg: float) -> SeenAxis:
    return SeenAxis(_leaning(deg), np.array([0.45, 0.0, 0.12]), 600)


async def test_a_leaning_rod_is_turned_straight_before_its_touch_down_and_set_down_turned():
    vision = FakeVision(seen(rod_at(0.5, 0.1)), held=(_axis(2.0),))
    cell = FakeCell(vision, config=_config())
    outcome = await cell.run(TaskKind.STAND_ROD)
    assert outcome.success
    (query,) = vision.held_queries
    assert query.rod_diameter_m == pytest.approx(0.022) and query.along_max_m > 0.1 + OFF_CENTRE
    moves = cell.moves()
    assert moves[moves.index("REORIENT") + 1 : moves.index("REORIENT") + 3] == ["STRAIGHTEN", "PLACE"]
    R = straightening(_leaning(2.0))
    (turn,) = cell.motion.labelled(["STRAIGHTEN"]).moves
    assert turn.kind is MotionKind.LINEAR and turn.held is not None  # the rod carried as it turns
    assert np.allclose(turn.target[:3, :3], R)  # the fake tool's rotation is the identity
    # the touch-down planned again from there, turned; what follows it too (about the touch-down)
    (place,) = cell.motion.labelled(["PLACE"]).moves
    assert np.allclose(place.target[:3, :3], R)
    retract = next(m for r in cell.motion.requests for m in r.moves if m.label == "RETRACT")
    assert np.allclose(retract.target[:3, :3], R)
    assert outcome.inline_compute_s >= 0.0 and outcome.stage_reached == "DONE"


@pytest.mark.parametrize(
    "held",
    [
        (_axis(0.3),),  # straight enough
        (_axis(20.0),),  # beyond what a grasp turns a rod: a wrong measure
        (CameraConnectionError("no frame within 2 s"),),  # not measured
    ],
)
async def test_a_rod_straight_enough_or_not_measured_is_set_down_as_it_hangs(held):
    vision = FakeVision(seen(rod_at(0.5, 0.1)), held=held)
    cell = FakeCell(vision, config=_config())
    outcome = await cell.run(TaskKind.STAND_ROD)
    assert outcome.success
    assert len(vision.held_queries) == 1
    assert "STRAIGHTEN" not in cell.moves()
    poses = [m.target for r in cell.motion.requests for m in r.moves if m.target.shape == (4, 4)]
    assert poses and all(np.array_equal(T[:3, :3], np.eye(3)) for T in poses)  # nothing turned


async def test_a_rod_grasped_at_its_centre_or_with_straightening_off_is_not_measured():
    centred = replace(_config(), grasp_offsets_m=(0.0,))
    for config in (centred, _config(from_offset=0.0)):
        vision = FakeVision(seen(rod_at(0.5, 0.1)), held=(_axis(2.0),))
        cell = FakeCell(vision, config=config)
        assert (await cell.run(TaskKind.STAND_ROD)).success
        assert vision.held_queries == [] and "STRAIGHTEN" not in cell.moves()
