"""The set-off cut into pieces whose tail the way on can replace (services.task.flow_on)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from services.kinematics.trajectory import JointTrajectory
from services.task.flow_on import FIRST_CUT_S, LAST_CUT_BEFORE_END_S, PIECE_PERIODS, cut_after, pieces

PERIOD = 0.03
NAMES = tuple(f"j{k}" for k in range(1, 7))


def _move(duration: float) -> JointTrajectory:
    """A rest-to-rest move of ``duration`` (a quintic: in motion everywhere between its ends)."""
    z = np.zeros((2, 6))
    q = np.vstack([np.zeros(6), np.linspace(0.2, 1.2, 6)])
    return JointTrajectory(NAMES, np.array([0.0, duration]), q, z, z.copy())


def test_the_cuts_fall_on_the_streaming_period_and_the_pieces_make_up_the_move() -> None:
    move = _move(0.8)
    parts = pieces(move, PERIOD)
    ends = np.cumsum([p.duration for p in parts])
    assert ends[-1] == pytest.approx(move.duration)
    cuts = ends[:-1]
    assert cuts[0] == pytest.approx(FIRST_CUT_S)  # one call up to there
    assert np.allclose(np.diff(cuts), PIECE_PERIODS * PERIOD)
    assert np.allclose(cuts / PERIOD, np.round(cuts / PERIOD))  # no streamed step shortened
    assert move.duration - cuts[-1] >= LAST_CUT_BEFORE_END_S - 1e-9
    assert move.duration - cuts[-1] < LAST_CUT_BEFORE_END_S + PIECE_PERIODS * PERIOD
    # each piece starts where and as fast as the one before ends; all but the last end in motion
    for a, b in itertools.pairwise(parts):
        assert np.allclose(a.positions[-1], b.positions[0]) and np.allclose(a.velocities[-1], b.velocities[0])
        assert a.ends_in_motion and b.starts_in_motion
    assert not parts[-1].ends_in_motion and np.array_equal(parts[-1].positions[-1], move.positions[-1])
    # the same motion: sampled through the pieces as through the whole
    t = 0.5
    k = int(np.searchsorted(ends, t))
    local = t - (ends[k - 1] if k else 0.0)
    assert np.allclose(parts[k].sample(local)[0], move.sample(t)[0])


def test_the_end_of_a_piece_is_where_the_arm_flows_on_from() -> None:
    parts = pieces(_move(0.8), PERIOD)
    cut = cut_after(parts, 2)
    assert cut is not None and cut.index == 2
    assert np.array_equal(cut.q, parts[2].positions[-1]) and np.array_equal(cut.qd, parts[2].velocities[-1])
    assert float(np.max(np.abs(cut.qd))) > 0.0
    assert cut_after(parts, len(parts) - 1) is None  # the last piece ends at rest
    assert cut_after(parts, -1) is None


def test_a_move_too_short_for_a_cut_goes_whole() -> None:
    move = _move(FIRST_CUT_S + LAST_CUT_BEFORE_END_S - 0.01)
    (only,) = pieces(move, PERIOD)
    assert only.duration == pytest.approx(move.duration) and not only.ends_in_motion
