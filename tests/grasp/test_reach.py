"""Batched IK tracking (services.grasp.reach.track_paths): each path judged on its own, whatever is
tracked beside it, and a jump named with the step that broke the last track."""

from __future__ import annotations

import math

import numpy as np

from services.grasp.reach import TrackLimits, origin_heights, track_paths
from services.kinematics.analytic import dh_matrices, fk
from services.kinematics.robot_models import get_robot

SPEC = get_robot("nova5")
LIMITS = TrackLimits(jump_threshold_rad=math.radians(10.0), arm_table_clearance_m=0.0, table_z_m=-1.0)
Q_A = np.radians([170.0, 20.0, 110.0, -40.0, -90.0, 30.0])
Q_B = np.radians([150.0, 30.0, 100.0, -30.0, -80.0, -20.0])
N = 30


def joint_line(q0: np.ndarray, q1: np.ndarray, n: int = N) -> np.ndarray:
    return q0 + np.linspace(0.0, 1.0, n)[:, None] * (q1 - q0)


def flange_path(q_path: np.ndarray) -> np.ndarray:
    return fk(SPEC, q_path)


def test_a_smooth_path_is_followed_in_the_branch_it_started_in() -> None:
    q_path = joint_line(Q_A, Q_B)
    res = track_paths(SPEC, flange_path(q_path)[None], Q_A, LIMITS)
    assert res.ok[0] and res.reason[0] == ""
    assert np.allclose(res.q[0], q_path, atol=1e-6)
    assert res.fail_index[0] == -1


def test_each_path_gets_the_answer_it_gets_alone() -> None:
    smooth = flange_path(joint_line(Q_A, Q_B))
    jumped = smooth.copy()
    jumped[N // 2 :] = flange_path(joint_line(Q_A, Q_B)[N // 2 :] + np.radians([60.0, 0, 0, 0, 0, 0]))
    other = flange_path(joint_line(Q_B, Q_A))
    batch = track_paths(SPEC, np.stack([smooth, jumped, other]), Q_A, LIMITS)
    for b, path in enumerate((smooth, jumped, other)):
        alone = track_paths(SPEC, path[None], Q_A, LIMITS)
        assert batch.ok[b] == alone.ok[0]
        assert batch.reason[b] == alone.reason[0]
        assert batch.fail_index[b] == alone.fail_index[0]
        if alone.ok[0]:
            assert np.allclose(batch.q[b], alone.q[0]) and math.isclose(batch.cost[b], alone.cost[0])
    assert batch.ok.tolist() == [True, False, True]


def test_a_jump_is_named_with_the_step_that_ended_the_last_track() -> None:
    q_path = joint_line(Q_A, Q_B)
    q_path[N // 2 :, 0] += math.radians(60.0)  # the base turns 60° between two samples
    res = track_paths(SPEC, flange_path(q_path)[None], Q_A, LIMITS, [f"s{k}" for k in range(N)])
    assert not res.ok[0]
    assert res.fail_index[0] == N // 2
    assert f"at s{N // 2}," in res.reason[0] and "would jump" in res.reason[0]
    step_deg = float(res.reason[0].split(", ")[-1].split("°")[0])
    assert step_deg > 10.0  # above the threshold it broke (not a step of a track that died earlier)


def test_origin_heights_are_the_joint_frames_heights() -> None:
    """The table check's heights, carried as one row through the chain, are those of the full DH
    transforms, and the last is the flange's."""
    spec = get_robot("nova5")
    q = np.random.default_rng(5).uniform(-3.0, 3.0, (20, 30, 6))
    theta = q + spec.theta_offset
    T = dh_matrices(spec, theta[..., 0], 0)
    want = [T[..., 2, 3]]
    for i in range(1, spec.dof):
        T = T @ dh_matrices(spec, theta[..., i], i)
        want.append(T[..., 2, 3])
    got = origin_heights(spec, q)
    assert np.allclose(got, np.stack(want, axis=-1), atol=1e-12)
    assert np.allclose(got[..., -1], fk(spec, q)[..., 2, 3], atol=1e-12)
