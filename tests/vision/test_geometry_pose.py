"""Back-projection, the RANSAC table plane, and the PCA pose estimator (LLD §3.4.1)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError, PoseEstimationError, VisionError
from services.common.sensors import CameraIntrinsics
from services.vision.geometry import Plane, backproject, fit_plane_ransac, pixel_rays, project
from services.vision.pose import estimate_pca_pose, rotation_to_quaternion

INTR = CameraIntrinsics(width=64, height=48, fx=60.0, fy=61.0, cx=31.5, cy=23.0)


def test_backprojection_inverts_projection():
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.4, 1.2, (48, 64)).astype(np.float32)
    depth[5, 7] = 0.0  # a hole is skipped
    pts, rows, cols = backproject(depth, INTR)
    assert len(pts) == 48 * 64 - 1
    assert not np.any((rows == 5) & (cols == 7))
    uv = project(pts, INTR)
    np.testing.assert_allclose(uv[:, 0], cols, atol=1e-4)
    np.testing.assert_allclose(uv[:, 1], rows, atol=1e-4)
    np.testing.assert_allclose(pts[:, 2], depth[rows, cols], rtol=1e-6)


def test_backprojection_stride_mask_and_range():
    depth = np.full((48, 64), 0.8, np.float32)
    depth[:, 32:] = 2.0
    mask = np.zeros((48, 64), bool)
    mask[:24] = True
    pts, rows, cols = backproject(depth, INTR, stride=2, mask=mask, z_max=1.5)
    assert np.all(rows % 2 == 0) and np.all(cols % 2 == 0)
    assert np.all(rows < 24) and np.all(cols < 32)
    assert len(pts) == 12 * 16


def test_ransac_plane_with_outliers_and_orientation():
    rng = np.random.default_rng(1)
    n_true = np.array([0.1, -0.8, -0.5])
    n_true /= np.linalg.norm(n_true)
    d_true = 0.7  # camera origin is on the positive side
    # points on the plane: pick x, y and solve z
    xy = rng.uniform(-0.4, 0.4, (5000, 2))
    z = -(d_true + xy @ n_true[:2]) / n_true[2]
    pts = np.column_stack([xy, z]) + rng.normal(0, 0.002, (5000, 3))
    outliers = rng.uniform(-0.5, 0.5, (2000, 3)) + [0, 0, 1.0]
    plane = fit_plane_ransac(np.vstack([pts, outliers]), 0.008, rng=np.random.default_rng(2))
    assert plane.d > 0
    assert np.degrees(np.arccos(plane.normal @ n_true)) < 0.2
    assert abs(plane.d - d_true) < 0.001
    assert 0.6 < plane.inlier_fraction < 0.8
    # intersecting rays with the plane lands on it
    rays = pixel_rays(INTR, np.array([10, 20]), np.array([5, 40]))
    hits = plane.intersect_rays(rays)
    np.testing.assert_allclose(plane.signed_distance(hits), 0.0, atol=1e-9)


def test_ransac_rejects_planeless_clouds_and_bad_shapes():
    rng = np.random.default_rng(3)
    with pytest.raises(VisionError, match="no table plane"):
        fit_plane_ransac(rng.uniform(-1, 1, (3000, 3)), 0.002, min_inlier_fraction=0.5)
    with pytest.raises(VisionError, match="at least 3"):
        fit_plane_ransac(np.zeros((2, 3)), 0.01)
    with pytest.raises(InvalidInputError, match=r"\(N, 3\)"):
        fit_plane_ransac(np.zeros((10, 2)), 0.01)


def test_plane_projection():
    plane = Plane(normal=np.array([0.0, 0.0, -1.0]), d=1.0)  # z = 1, camera side toward -z
    p = plane.project(np.array([[0.2, 0.1, 0.7]]))
    np.testing.assert_allclose(p, [[0.2, 0.1, 1.0]])
    assert plane.signed_distance(np.array([[0, 0, 0.9]]))[0] == pytest.approx(0.1)


def test_pca_pose_of_an_elongated_box():
    rng = np.random.default_rng(4)
    R_true = Rotation.from_euler("xyz", [20, -35, 60], degrees=True).as_matrix()
    local = rng.uniform([-0.1, -0.02, -0.005], [0.1, 0.02, 0.005], (4000, 3))
    pts = local @ R_true.T + [0.3, -0.1, 0.8]
    pose = estimate_pca_pose(pts)
    np.testing.assert_allclose(pose.position, [0.3, -0.1, 0.8], atol=0.003)
    for k in range(3):  # each principal axis matches the true one up to sign
        assert abs(pose.rotation[:, k] @ R_true[:, k]) > 0.999
    assert np.linalg.det(pose.rotation) == pytest.approx(1.0)
    assert pose.eigenvalues[0] > pose.eigenvalues[1] > pose.eigenvalues[2]
    np.testing.assert_allclose(Rotation.from_quat(pose.quat_xyzw).as_matrix(), pose.rotation, atol=1e-9)
    assert pose.quat_xyzw[3] >= 0
    # the result does not depend on the order of the points
    again = estimate_pca_pose(pts[rng.permutation(len(pts))])
    np.testing.assert_allclose(again.rotation, pose.rotation, atol=1e-9)


def test_pca_pose_rejects_bad_input():
    with pytest.raises(PoseEstimationError, match="at least 10"):
        estimate_pca_pose(np.zeros((5, 3)))
    with pytest.raises(PoseEstimationError, match="coincide"):
        estimate_pca_pose(np.ones((20, 3)))
    bad = np.zeros((20, 3))
    bad[3, 1] = np.nan
    with pytest.raises(InvalidInputError, match="NaN"):
        estimate_pca_pose(bad)
    with pytest.raises(InvalidInputError, match=r"\(N, 3\)"):
        estimate_pca_pose(np.zeros((20, 2)))


def test_rotation_to_quaternion_validates():
    with pytest.raises(InvalidInputError, match="orthonormal"):
        rotation_to_quaternion(np.diag([1.0, 1.0, -1.0]))  # a reflection
    with pytest.raises(InvalidInputError, match="orthonormal"):
        rotation_to_quaternion(np.eye(3) * 1.1)
    with pytest.raises(InvalidInputError, match="3x3"):
        rotation_to_quaternion(np.eye(4))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1))
def test_quaternion_round_trip(q):
    R = Rotation.from_quat(np.array(q) / np.linalg.norm(q)).as_matrix()
    quat = rotation_to_quaternion(R)
    assert quat[3] >= 0
    assert np.linalg.norm(quat) == pytest.approx(1.0)
    np.testing.assert_allclose(Rotation.from_quat(quat).as_matrix(), R, atol=1e-9)
