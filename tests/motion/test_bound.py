"""The eval's bound: no motion through the waypoints at the limits is faster, and it is tight where a
single joint decides."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.errors import InvalidInputError
from services.kinematics.robot_models import NOVA5
from services.kinematics.trajectory import JointLimits
from services.motion.bound import one_joint_move_s, stop_to_stop_s, through_waypoints_s, turning_points
from services.motion.timing import rest_to_rest, time_parameterize

LIMITS = JointLimits.from_spec(NOVA5)
NAMES = list(NOVA5.joint_names)
HOME = np.deg2rad([180.0, 0.0, 90.0, 0.0, -90.0, 0.0])


def _base_moves(*deg: float) -> np.ndarray:
    """Waypoints where only the base turns, through ``deg`` off the home pose."""
    return np.array([HOME + np.deg2rad([d, 0, 0, 0, 0, 0]) for d in deg])


def _base_alone(a_deg: float, b_deg: float) -> float:
    lim = LIMITS
    assert lim.max_jerk is not None
    a, b = np.deg2rad([a_deg, b_deg])
    return one_joint_move_s(a, b, lim.max_velocity[0], lim.max_acceleration[0], lim.max_jerk[0])


def test_a_joints_turning_points_are_where_it_turns_back():
    assert turning_points(np.array([0.0, 0.2, 0.5, 0.5, 0.3, 0.1, 0.4])).tolist() == [0.0, 0.5, 0.1, 0.4]
    assert turning_points(np.array([0.3, 0.3, 0.3])).tolist() == [0.3]
    assert turning_points(np.array([0.0, 1.0])).tolist() == [0.0, 1.0]


def test_flowing_on_in_one_direction_is_one_move_and_beats_stopping_at_each_waypoint():
    path = _base_moves(0, 20, 40, 60)
    bound = through_waypoints_s(path, LIMITS)
    assert bound == pytest.approx(_base_alone(0, 60), rel=1e-9)
    assert bound < rest_to_rest(path, LIMITS, NAMES).duration - 0.3  # three stops cost that much more


def test_a_joint_that_turns_back_swings_through_its_turn_at_zero_speed():
    from services.motion.bound import _swing_s

    path = _base_moves(0, 40, 10)
    bound = through_waypoints_s(path, LIMITS)
    # faster than halting there (zero acceleration too), slower than an acceleration that may jump
    assert bound < _base_alone(0, 40) + _base_alone(40, 10) - 0.05
    v, a, j = LIMITS.max_velocity[0], LIMITS.max_acceleration[0], LIMITS.max_jerk[0]  # type: ignore[index]
    x0, xt, x1 = np.deg2rad([0.0, 40.0, 10.0])
    assert bound > one_joint_move_s(x0, xt, v, a, None) + one_joint_move_s(xt, x1, v, a, None)
    # the least over a fine scan of the turn's acceleration: a jerk-limited motion that exists (two
    # ruckig moves meeting at the turn at zero speed and that acceleration); the grid's is within 0.1 %
    swings = [
        _swing_s(x0, 0.0, xt, at, v, a, j) + _swing_s(xt, at, x1, 0.0, v, a, j)
        for at in np.linspace(-a, a, 2001)
    ]
    assert min(swings) - 1e-9 <= bound <= min(swings) * 1.001
    # resting at every waypoint: each run its own
    assert stop_to_stop_s(path, [True, True, True], LIMITS) == pytest.approx(
        _base_alone(0, 40) + _base_alone(40, 10)
    )


@pytest.mark.parametrize("seed", range(6))
def test_no_motion_through_the_waypoints_within_the_limits_is_faster(seed: int):
    rng = np.random.default_rng(seed)
    path = HOME + np.cumsum(rng.uniform(-0.5, 0.5, size=(5, 6)), axis=0)
    path = np.clip(path, LIMITS.lower + 0.1, LIMITS.upper - 0.1)
    bound = through_waypoints_s(path, LIMITS)
    # a timing through the same waypoints (a spline through each, verified against the limits)
    spline = time_parameterize(path, LIMITS, NAMES, method="toppra")
    assert 0 < bound <= spline.duration
    assert bound <= rest_to_rest(path, LIMITS, NAMES).duration
    # resting somewhere on the way only takes longer
    assert stop_to_stop_s(path, [True, False, True, False, True], LIMITS) >= bound - 1e-9


def test_rest_flags_must_match_the_waypoints():
    with pytest.raises(InvalidInputError, match="2 rest flags for 3 waypoints"):
        stop_to_stop_s(_base_moves(0, 10, 20), [True, True], LIMITS)


def test_a_floor_counts_for_a_move_from_rest_to_rest_where_it_is_more():
    path = _base_moves(0, 40, 10)
    joints = stop_to_stop_s(path, [True, True, True], LIMITS)
    slow_second = _base_alone(40, 10) + 0.5
    assert stop_to_stop_s(path, [True, True, True], LIMITS, floors={2: slow_second}) == pytest.approx(
        _base_alone(0, 40) + slow_second
    )
    assert stop_to_stop_s(path, [True, True, True], LIMITS, floors={2: 0.01}) == pytest.approx(joints)
    # flowed into from a move before it: not from rest, so its floor does not hold there
    assert stop_to_stop_s(path, [True, False, True], LIMITS, floors={2: 10.0}) == pytest.approx(
        stop_to_stop_s(path, [True, False, True], LIMITS)
    )
