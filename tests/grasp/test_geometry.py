"""Tool-line poses: the closed-form slerp agrees with scipy's, a half turn goes scipy's way round."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from services.grasp.geometry import pose_path, pose_paths


def _reference(T_a: np.ndarray, T_b: np.ndarray, n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)
    return Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([T_a[:3, :3], T_b[:3, :3]])))(s).as_matrix()


def test_pose_path_orientations_are_scipys_slerp() -> None:
    rng = np.random.default_rng(7)
    for k in range(300):
        T_a, T_b = np.eye(4), np.eye(4)
        T_a[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        turn = Rotation.from_rotvec(rng.normal(size=3)) if k % 2 else Rotation.random(random_state=rng)
        T_b[:3, :3] = T_a[:3, :3] @ turn.as_matrix()
        T_b[:3, 3] = [0.1, -0.05, 0.2]
        path = pose_path(T_a, T_b, 0.01)
        assert np.allclose(path[:, :3, :3], _reference(T_a, T_b, len(path)), atol=1e-6)
        assert np.allclose(path[[0, -1]], np.stack([T_a, T_b]))
        assert np.allclose(np.diff(path[:, :3, 3], axis=0), (T_b[:3, 3] - T_a[:3, 3]) / (len(path) - 1))


def test_a_half_turn_goes_the_same_way_round_as_scipy() -> None:
    """Either way round ends at a half turn; the grasp planner and motion must agree on which."""
    rng = np.random.default_rng(1)
    for k in range(200):
        axis = np.eye(3)[k] if k < 3 else rng.normal(size=3)
        T_a, T_b = np.eye(4), np.eye(4)
        T_a[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        T_b[:3, :3] = T_a[:3, :3] @ Rotation.from_rotvec(np.pi * axis / np.linalg.norm(axis)).as_matrix()
        path = pose_path(T_a, T_b, 0.01, n=8)
        assert np.allclose(path[:, :3, :3], _reference(T_a, T_b, 9), atol=1e-6)


def test_pose_paths_give_each_pairs_pose_path() -> None:
    """The batched lines the rod planner samples every option with: each pair's own pose_path,
    a pair without a turn and one at a half turn (scipy's way round) among them."""
    rng = np.random.default_rng(3)
    B = 60
    T_a, T_b = np.tile(np.eye(4), (B, 1, 1)), np.tile(np.eye(4), (B, 1, 1))
    T_a[:, :3, :3] = Rotation.random(B, random_state=rng).as_matrix()
    T_b[:, :3, :3] = Rotation.random(B, random_state=rng).as_matrix()
    T_b[1, :3, :3] = T_a[1, :3, :3]
    T_b[2, :3, :3] = T_a[2, :3, :3] @ Rotation.from_rotvec([0.0, np.pi, 0.0]).as_matrix()
    T_a[:, :3, 3], T_b[:, :3, 3] = rng.normal(size=(B, 3)), rng.normal(size=(B, 3))
    got = pose_paths(T_a, T_b, 7)
    assert got.shape == (B, 8, 4, 4)
    for b in range(B):
        assert np.allclose(got[b], pose_path(T_a[b], T_b[b], 1.0, 7), atol=1e-12)
