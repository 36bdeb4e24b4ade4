import numpy as np
import pytest

from services.common.errors import InvalidInputError
from services.common.frames import (
    check_transform,
    dobot_pose_to_transform,
    finite_vector,
    invert_transform,
    matrix_to_quat_xyzw,
    quat_xyzw_to_matrix,
    transform_to_dobot_pose,
)


def test_dobot_pose_round_trip():
    rng = np.random.default_rng(1)
    for _ in range(50):
        pose = np.concatenate([rng.uniform(-800, 800, 3), rng.uniform(-170, 170, 3)])
        pose[4] = rng.uniform(-80, 80)  # away from the pitch singularity
        T = dobot_pose_to_transform(pose)
        check_transform(T)
        assert np.allclose(transform_to_dobot_pose(T), pose, atol=1e-9)


def test_euler_convention_is_fixed_xyz():
    # R = Rz(rz) Ry(ry) Rx(rx): rotating x by rz=90 only maps +x to +y
    T = dobot_pose_to_transform([0, 0, 0, 0, 0, 90])
    assert np.allclose(T[:3, :3] @ [1, 0, 0], [0, 1, 0])
    T = dobot_pose_to_transform([0, 0, 0, 90, 0, 90])
    Rx = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    Rz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert np.allclose(T[:3, :3], Rz @ Rx)


def test_quaternion_and_inverse():
    T = dobot_pose_to_transform([100, -50, 300, 10, 20, 30])
    q = matrix_to_quat_xyzw(T[:3, :3])
    assert np.allclose(quat_xyzw_to_matrix(q), T[:3, :3])
    assert np.allclose(invert_transform(T) @ T, np.eye(4))


def test_bad_input_named():
    with pytest.raises(InvalidInputError, match="NaN"):
        finite_vector([1, float("nan"), 3], 3, "target")
    with pytest.raises(InvalidInputError, match="must have 6 values"):
        finite_vector([1, 2], 6, "joints")
    bad = np.eye(4)
    bad[0, 0] = 2
    with pytest.raises(InvalidInputError, match="orthonormal"):
        check_transform(bad)
