"""UR pose vectors ↔ transforms agree with scipy's rotation vectors, half turns included."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from services.rtde.poses import pose_to_transform, transform_to_pose


def test_round_trips_match_scipy_on_random_poses() -> None:
    rng = np.random.default_rng(7)
    for rv in Rotation.random(200, random_state=rng).as_rotvec():
        pose = np.concatenate([rng.normal(size=3), rv])
        T = pose_to_transform(pose)
        assert np.allclose(T[:3, :3], Rotation.from_rotvec(rv).as_matrix(), atol=1e-12)
        assert np.allclose(transform_to_pose(T), pose, atol=1e-9)


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, -1, 0), (-1, 2, 3)])
def test_half_turns_and_identity_come_back_as_the_same_rotation(axis: tuple[float, ...]) -> None:
    k = np.array(axis, dtype=float) / np.linalg.norm(axis)
    for angle in (0.0, np.pi, np.pi - 1e-8, np.pi - 3.6e-6, np.pi - 1e-3, 2.0, 2.5):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(angle * k).as_matrix()
        back = pose_to_transform(transform_to_pose(T))
        assert np.allclose(back, T, atol=1e-12)


def test_a_bad_pose_is_refused_naming_the_shape() -> None:
    with pytest.raises(ValueError, match="6 finite numbers"):
        pose_to_transform([0.0, 0.0, float("nan"), 0.0, 0.0, 0.0])
