"""Rounded corners of a blended run: the curve's geometry, and the planner's use of it (faster, within
the tool tolerance, refused where it would collide)."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from services.kinematics.collision import Scene
from services.kinematics.interpolation import arc_lengths, densify
from services.kinematics.model import load_arm
from services.kinematics.trajectory import verify_trajectory
from services.motion.corners import max_rounding, round_corner, with_corners
from services.motion.planner import BlendPart, MotionPlanner, blend

Q_PICK = np.deg2rad([162.5, 22.6, 129.3, -61.9, -90.0, -107.5])
PERIOD = 0.03


def _right_angle(step: float = 0.05) -> np.ndarray:
    """Joint 1 out by 0.5 rad, then joint 2 out by 0.5 rad: a right-angle corner at row 10."""
    out = [np.zeros(6)]
    for k in range(1, 11):
        out.append(np.array([k * step, 0, 0, 0, 0, 0]))
    for k in range(1, 11):
        out.append(np.array([0.5, k * step, 0, 0, 0, 0]))
    return np.array(out)


def test_a_rounded_corner_leaves_and_rejoins_the_path_tangentially_inside_the_corner():
    rows = _right_angle()
    s = arc_lengths(rows)
    found = round_corner(rows, s, 10, 0.2, 0.05)
    assert found is not None
    a, b = found.curve[0], found.curve[-1]
    assert np.allclose(a, [0.3, 0, 0, 0, 0, 0]) and np.allclose(b, [0.5, 0.2, 0, 0, 0, 0])
    # tangent to the path where it leaves and where it rejoins it
    start_dir = found.curve[1] - found.curve[0]
    end_dir = found.curve[-1] - found.curve[-2]
    assert start_dir[1] / start_dir[0] < 0.2 and end_dir[0] / end_dir[1] < 0.2
    # inside the corner's triangle, never past the corner, and it does cut the corner
    assert np.all(found.curve[:, 0] <= 0.5 + 1e-12) and np.all(found.curve[:, 1] >= -1e-12)
    assert min(np.linalg.norm(found.curve - rows[10], axis=1)) > 0.05
    # no step larger than asked
    assert np.max(np.linalg.norm(np.diff(found.curve, axis=0), axis=1)) <= 0.05 + 1e-9
    rounded = with_corners(rows, [found])
    assert np.allclose(rounded[0], rows[0]) and np.allclose(rounded[-1], rows[-1])
    assert not any(np.allclose(r, rows[10]) for r in rounded)  # the corner itself is gone
    assert np.all(np.linalg.norm(np.diff(rounded, axis=0), axis=1) > 0.0125)  # nothing crowded


def test_neighbouring_roundings_never_overlap_and_a_tiny_one_is_not_made():
    rows = np.vstack([_right_angle(), [[0.5, 0.5 + 0.02, 0, 0, 0, 0]]])  # a last, 2 cm piece
    s = arc_lengths(rows)
    corners = [10, 20]
    first = round_corner(rows, s, 10, max_rounding(s, corners, 0), 0.05)
    assert first is not None and max_rounding(s, corners, 0) == pytest.approx(0.45 * 0.5)
    assert round_corner(rows, s, 20, max_rounding(s, corners, 1), 0.05) is None  # 0.45 × 2 cm: nothing
    assert round_corner(rows, s, 0, 0.1, 0.05) is None  # an end is no corner


@pytest.fixture(scope="module")
def planner():
    return MotionPlanner(load_arm("nova5"), Scene())


def _run(planner: MotionPlanner, tolerance: float) -> list[BlendPart]:
    """A joint move to above the pick, a 6 cm line up, a joint swing: two corners."""
    q_mid = Q_PICK + np.deg2rad([30, 0, 0, 0, 0, 0])
    up = planner.kin.fk(Q_PICK)
    up[2, 3] += 0.06
    first = planner.joints_path(q_mid, Q_PICK)
    line = planner.line_path(Q_PICK, [up])
    swing = planner.joints_path(line.path[-1], line.path[-1] + np.deg2rad([-60, 10, -10, 0, 0, 0]))
    return [
        BlendPart(planner, first, False, tolerance),
        BlendPart(planner, line, True, tolerance),
        BlendPart(planner, swing, False, 0.0),
    ]


def test_rounded_corners_make_the_blend_faster_and_keep_the_tool_within_the_tolerance(planner):
    flat, why = blend(_run(planner, 0.0), PERIOD)
    assert flat is not None, why
    tol = 0.01
    parts = _run(planner, tol)
    rounded, why = blend(parts, PERIOD)
    assert rounded is not None, why
    duration = sum(p.duration for p in rounded)
    assert duration < 0.95 * sum(p.duration for p in flat)
    whole = rounded[0]
    for piece in rounded[1:]:
        whole = whole.append(piece)
    assert np.allclose(whole.positions[0], parts[0].path[0]) and np.allclose(
        whole.positions[-1], parts[-1].path[-1]
    )
    verify_trajectory(whole, planner.line_limits)
    for a, b in itertools.pairwise(rounded):  # flowing on at every cut
        assert np.allclose(a.positions[-1], b.positions[0]) and np.max(np.abs(a.velocities[-1])) > 1e-3
    # every tool point of the motion lies within the tolerance of the path it was planned along
    path = np.vstack(
        [parts[0].path[:1], *(densify(p.path, planner.config.spline_segment_rad)[1:] for p in parts)]
    )
    fine = np.vstack([a + u * (b - a) for a, b in itertools.pairwise(path) for u in np.linspace(0, 1, 20)])
    ref = np.array([planner.kin.fk(q)[:3, 3] for q in fine])
    got = np.array([planner.kin.fk(q)[:3, 3] for q in whole.positions[::3]])
    deviation = np.max(np.min(np.linalg.norm(got[:, None] - ref[None], axis=2), axis=1))
    assert 1e-3 < deviation <= tol + 1e-3  # it did round, and no further than allowed


def test_a_rounding_that_would_collide_in_either_scene_is_not_taken(planner, monkeypatch):
    flat, _ = blend(_run(planner, 0.0), PERIOD)
    assert flat is not None
    parts = _run(planner, 0.01)
    other = MotionPlanner(planner.arm, Scene())  # the next move's own scene, where the curve "hits"
    parts[1] = dataclasses.replace(parts[1], planner=other)
    parts[2] = dataclasses.replace(parts[2], planner=other)
    checked: list[int] = []

    def hits(path, resolution_rad):
        checked.append(len(path))
        return 0, np.asarray(path)[0]

    monkeypatch.setattr(other.checker, "first_collision_on_path", hits)
    pieces, why = blend(parts, PERIOD)
    assert pieces is not None, why
    assert checked  # the curves were checked in the next move's scene, and every one refused
    assert sum(p.duration for p in pieces) == pytest.approx(sum(p.duration for p in flat), abs=1e-6)


def test_a_rounded_blend_whose_timed_motion_touches_something_flows_through_the_waypoints_instead(
    planner, monkeypatch
):
    flat, _ = blend(_run(planner, 0.0), PERIOD)
    assert flat is not None
    parts = _run(planner, 0.01)
    checks = planner.checker.first_collision_in_trajectory
    calls: list[float] = []

    def first_touches(traj, resolution_rad):
        calls.append(traj.duration)
        if len(calls) == 1:  # the rounded motion's first piece
            return 0.0, traj.positions[0]
        return checks(traj, resolution_rad)

    monkeypatch.setattr(planner.checker, "first_collision_in_trajectory", first_touches)
    pieces, why = blend(parts, PERIOD)
    assert pieces is not None, why  # not refused: blended still, through the waypoints
    assert sum(p.duration for p in pieces) == pytest.approx(sum(p.duration for p in flat), abs=1e-6)
    assert len(calls) == 1 + len(parts)  # the rounded one stopped at its first piece, then each again
