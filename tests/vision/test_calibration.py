"""Eye-to-hand calibration: manual pose, the solve, the ChArUco board, the file, drift, the whole run."""

from __future__ import annotations

import asyncio
import datetime as dt

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from services.common.camera_pose import manual_T_base_camera, read_calibration
from services.common.charuco import CharucoTarget, default_T_gripper_board
from services.common.errors import ConfigurationError, InvalidInputError, RobotError, VisionError
from services.common.frames import invert_transform, make_transform
from services.common.sensors import RGBDFrame
from services.common.settings import CalibrationBoardSettings, CalibrationSettings
from services.vision.calibrate_workflow import (
    check_calibration,
    generate_calibration_poses,
    run_calibration,
)
from services.vision.calibration import (
    calibration_record,
    check_drift,
    hand_eye_backends,
    solve_eye_to_hand,
    write_calibration,
)
from services.vision.synthetic import d435_intrinsics, look_at_camera, render_planar_target

TRANS_TOL_M = 0.002
ROT_TOL_DEG = 0.5


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    dt_m = float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
    dr = float(np.degrees(Rotation.from_matrix(T_est[:3, :3].T @ T_true[:3, :3]).magnitude()))
    return dt_m, dr


def jitter(T: np.ndarray, rng: np.random.Generator, sigma_m: float, sigma_deg: float) -> np.ndarray:
    out = T.copy()
    out[:3, 3] += rng.normal(0.0, sigma_m, 3)
    out[:3, :3] = out[:3, :3] @ Rotation.from_rotvec(rng.normal(0.0, np.deg2rad(sigma_deg), 3)).as_matrix()
    return out


def synthetic_views(seed: int, n: int, cam_noise=(0.0, 0.0), robot_noise=(0.0, 0.0)):
    """Robot poses and board poses consistent with a known camera and board mount (+ optional noise)."""
    rng = np.random.default_rng(seed)
    X = look_at_camera(
        np.array([0.45, 0.0, 0.0]), rng.uniform(0.7, 0.9), rng.uniform(50, 60), rng.uniform(-10, 10)
    )
    Y = make_transform(
        Rotation.from_euler("xyz", rng.uniform(-20, 20, 3), degrees=True).as_matrix(),
        rng.uniform(-0.05, 0.05, 3),
    )
    G, C = [], []
    for _ in range(n):
        R = Rotation.from_euler(
            "xyz", [180 + rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-60, 60)], degrees=True
        ).as_matrix()
        g = make_transform(R, rng.uniform([0.3, -0.2, 0.1], [0.55, 0.2, 0.3]))
        c = invert_transform(X) @ g @ Y
        G.append(jitter(g, rng, *robot_noise))
        C.append(jitter(c, rng, *cam_noise))
    return X, Y, G, C


def test_manual_transform_is_validated():
    T = manual_T_base_camera([0.9, 0.0, 0.65], rpy_deg=[-145.0, 0.0, 90.0])
    assert T.shape == (4, 4) and np.allclose(T[:3, 3], [0.9, 0.0, 0.65])
    q = Rotation.from_matrix(T[:3, :3]).as_quat()
    np.testing.assert_allclose(manual_T_base_camera([0.9, 0.0, 0.65], quat_xyzw=q), T, atol=1e-12)
    with pytest.raises(InvalidInputError, match="NaN"):
        manual_T_base_camera([np.nan, 0, 0], rpy_deg=[0, 0, 0])
    with pytest.raises(InvalidInputError, match="exactly one"):
        manual_T_base_camera([0, 0, 1], rpy_deg=[0, 0, 0], quat_xyzw=[0, 0, 0, 1])
    with pytest.raises(InvalidInputError, match="unit length"):
        manual_T_base_camera([0, 0, 1], quat_xyzw=[0, 0, 0, 2])
    with pytest.raises(InvalidInputError, match="units"):
        manual_T_base_camera([900, 0, 650], rpy_deg=[0, 0, 0])  # millimetres by mistake


@pytest.mark.parametrize("backend", hand_eye_backends())
def test_exact_data_recovers_the_transform_exactly(backend):
    X, Y, G, C = synthetic_views(0, 8)
    result = solve_eye_to_hand(G, C, refine=False, backend=backend)
    dt_m, dr = pose_error(result.T_base_camera, X)
    assert dt_m < 1e-6 and dr < 1e-5
    assert pose_error(result.T_gripper_board, Y)[0] < 1e-6
    assert result.translation_max_m < 1e-6


@pytest.mark.parametrize("seed", range(5))
def test_noisy_observations_recover_the_transform_within_2mm_half_degree(seed):
    # camera board poses: 0.4 mm / 0.1° per axis (PnP at ~0.7 m); robot: 0.1 mm / 0.02°
    X, _, G, C = synthetic_views(seed, 20, cam_noise=(0.0004, 0.1), robot_noise=(0.0001, 0.02))
    result = solve_eye_to_hand(G, C)
    dt_m, dr = pose_error(result.T_base_camera, X)
    assert dt_m <= TRANS_TOL_M and dr <= ROT_TOL_DEG, (dt_m, dr)
    assert result.method.endswith("+refined") and result.n_poses == 20
    assert 0 < result.translation_rms_m < 0.005  # the residual report reflects the noise


def test_a_board_mounted_face_out_at_180_degrees_is_recovered_by_the_refinement():
    # A mount rotated exactly 180° (board face out from the flange) is where a rotation-vector
    # parametrisation is singular; the refinement must still land on it, given noisy views.
    X, _, G0, _ = synthetic_views(3, 10)
    Y = make_transform(Rotation.from_euler("x", 180.0, degrees=True).as_matrix(), [-0.09, -0.06, 0.18])
    rng = np.random.default_rng(3)
    C = [jitter(invert_transform(X) @ g @ Y, rng, 0.0003, 0.05) for g in G0]
    grid = np.array([[x, y, 0.0] for x in (0.03, 0.06, 0.09, 0.12) for y in (0.03, 0.09, 0.15)])
    result = solve_eye_to_hand(G0, C, board_points=grid)
    assert pose_error(result.T_base_camera, X)[1] <= ROT_TOL_DEG
    dy_m, dy_deg = pose_error(result.T_gripper_board, Y)
    assert dy_m <= TRANS_TOL_M and dy_deg <= ROT_TOL_DEG, (dy_m, dy_deg)
    with pytest.raises(InvalidInputError, match="spanning a plane"):
        solve_eye_to_hand(G0, C, board_points=grid[grid[:, 0] == 0.03])  # one column of the grid: a line


def test_degenerate_and_mismatched_inputs_are_rejected():
    X, Y, G, C = synthetic_views(1, 6)
    same_axis = [
        make_transform(Rotation.from_euler("z", a, degrees=True).as_matrix(), [0.4, 0.0, 0.2])
        for a in (0, 20, 40, 60)
    ]
    with pytest.raises(VisionError, match="two different axes"):
        solve_eye_to_hand(same_axis, [invert_transform(X) @ g @ Y for g in same_axis])
    with pytest.raises(InvalidInputError, match="one board observation per robot pose"):
        solve_eye_to_hand(G, C[:-1])
    with pytest.raises(InvalidInputError, match="at least 3"):
        solve_eye_to_hand(G[:2], C[:2])
    bad = [g.copy() for g in G]
    bad[2][0, 0] = 3.0
    with pytest.raises(InvalidInputError, match=r"T_base_gripper\[2\]"):
        solve_eye_to_hand(bad, C)
    with pytest.raises(ConfigurationError, match="not available"):
        solve_eye_to_hand(G, C, backend="tsai-from-the-future")


def test_calibration_file_round_trip(tmp_path):
    _, _, G, C = synthetic_views(2, 10)
    result = solve_eye_to_hand(G, C)
    stamp = dt.datetime(2026, 1, 2, 3, 4, 5, tzinfo=dt.UTC)
    path = write_calibration(
        tmp_path / "cfg" / "calibration.yaml",
        calibration_record(result.T_base_camera, method=result.method, timestamp=stamp, result=result),
    )
    loaded = read_calibration(path)
    np.testing.assert_allclose(loaded.T_base_camera, result.T_base_camera, atol=1e-12)
    assert loaded.timestamp == stamp and loaded.method == result.method
    raw = yaml.safe_load(path.read_text())
    assert raw["n_poses"] == 10 and "translation_rms_m" in raw["residuals"]
    np.testing.assert_allclose(
        Rotation.from_quat(raw["quaternion_xyzw"]).as_matrix(), result.T_base_camera[:3, :3], atol=1e-9
    )


def test_bad_calibration_files_say_what_is_wrong(tmp_path):
    with pytest.raises(ConfigurationError, match="no calibration file"):
        read_calibration(tmp_path / "missing.yaml")
    p = tmp_path / "c.yaml"
    p.write_text("T_base_camera: [[1, 0], [0, 1]]\ntimestamp: 2026-01-01T00:00:00+00:00\n")
    with pytest.raises(ConfigurationError, match="4x4"):
        read_calibration(p)
    p.write_text("just text")
    with pytest.raises(ConfigurationError, match="no T_base_camera"):
        read_calibration(p)
    p.write_text(yaml.safe_dump({"T_base_camera": np.eye(4).tolist(), "timestamp": "yesterday"}))
    with pytest.raises(ConfigurationError, match="timestamp"):
        read_calibration(p)


def test_drift_check_passes_when_true_and_flags_a_moved_camera():
    X, Y, G, C = synthetic_views(3, 5, cam_noise=(0.0003, 0.05))
    report = check_drift(X, Y, G, C)
    assert report.ok and report.max_translation_m < 0.005 and "holds" in report.message
    bumped = X @ make_transform(Rotation.from_euler("x", 1.5, degrees=True).as_matrix(), [0.01, 0, 0])
    report = check_drift(bumped, Y, G, C)
    assert not report.ok and report.max_translation_m > 0.008 and "recalibrate" in report.message
    with pytest.raises(InvalidInputError, match="non-empty"):
        check_drift(X, Y, [], [])


def test_board_pose_from_a_rendered_view():
    target = CharucoTarget(CalibrationBoardSettings())
    intr = d435_intrinsics()
    rng = np.random.default_rng(5)
    for k in range(4):
        R = Rotation.from_euler("xyz", rng.uniform(-35, 35, 3), degrees=True).as_matrix()
        T = make_transform(
            R,
            np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.05, 0.05), rng.uniform(0.5, 0.8)])
            - R @ target.center_board,
        )
        view = render_planar_target(target.image(100), target.size_m, T, intr, seed=k)
        obs = target.detect(view, intr)
        assert obs is not None and len(obs.ids) >= 20
        dt_m, dr = pose_error(obs.T_camera_board, T)
        assert dt_m < 0.001 and dr < 0.3 and obs.reprojection_rms_px < 0.5
    assert target.detect(np.full((480, 640), 128, np.uint8), intr) is None  # nothing there
    with pytest.raises(InvalidInputError, match="grey or RGB"):
        target.detect(np.zeros((480, 640, 4), np.uint8), intr)
    with pytest.raises(ConfigurationError, match="dictionary"):
        CharucoTarget(CalibrationBoardSettings(dictionary="DICT_9X9_1"))


class FakeRobot:
    """Goes exactly where told; reports its pose with encoder-like noise; refuses one pose."""

    def __init__(self, rng: np.random.Generator, refuse: int | None = None):
        self.rng, self.refuse, self.moves, self.T = rng, refuse, 0, np.eye(4)

    async def move_to_pose(self, T_base_gripper: np.ndarray) -> None:
        self.moves += 1
        if self.moves == self.refuse:
            raise RobotError("IK failure: pose out of reach")
        self.T = T_base_gripper

    async def get_pose(self) -> np.ndarray:
        return jitter(self.T, self.rng, 0.0002, 0.02)


class BoardCamera:
    """Renders the board held by the fake robot, seen from the true camera pose."""

    def __init__(self, robot: FakeRobot, T_base_camera, T_gripper_board, target: CharucoTarget):
        self.robot, self.X, self.Y, self.target = robot, T_base_camera, T_gripper_board, target
        self.board_image = target.image(100)
        self.intrinsics = d435_intrinsics()
        self.n = 0

    def capture(self) -> RGBDFrame:
        self.n += 1
        T_cb = invert_transform(self.X) @ self.robot.T @ self.Y
        grey = render_planar_target(
            self.board_image,
            self.target.size_m,
            T_cb,
            self.intrinsics,
            seed=self.n,
            noise_sigma=3.0,
            blur_sigma=0.8,
        )
        depth = np.full(grey.shape, 700, np.uint16)
        return RGBDFrame(np.repeat(grey[..., None], 3, axis=2), depth, self.intrinsics, seq=self.n)

    def close(self) -> None:
        pass


@pytest.mark.parametrize("seed", range(3))
def test_end_to_end_calibration_run_recovers_the_true_camera(tmp_path, seed):
    rng = np.random.default_rng(seed)
    settings = CalibrationSettings()
    target = CharucoTarget(settings.board)
    X = look_at_camera(
        np.array([0.45, rng.uniform(-0.05, 0.05), 0.0]),
        rng.uniform(0.75, 0.9),
        rng.uniform(50, 60),
        rng.uniform(-10, 10),
    )
    # the board sits on the flange a little differently from the guess
    Y = default_T_gripper_board(target) @ jitter(np.eye(4), rng, 0.01, 5.0)
    robot = FakeRobot(rng, refuse=4)
    camera = BoardCamera(robot, X, Y, target)
    X_guess = X @ make_transform(Rotation.from_euler("z", 3, degrees=True).as_matrix(), [0.03, -0.02, 0.02])
    progress: list[tuple[int, int, str]] = []
    out = tmp_path / "calibration.yaml"
    result, data = asyncio.run(
        run_calibration(robot, camera, settings, X_guess, out, lambda *a: progress.append(a), seed=seed)
    )
    dt_m, dr = pose_error(result.T_base_camera, X)
    assert dt_m <= TRANS_TOL_M and dr <= ROT_TOL_DEG, (dt_m, dr)
    assert result.reprojection_rms_px is not None and result.reprojection_rms_px < 1.5
    assert [p[0] for p in progress] == list(range(1, settings.n_poses + 1))
    assert any("could not reach" in s for s in data.skipped)
    assert result.n_poses == len(data.observations) >= settings.n_poses - 3
    saved = read_calibration(out)
    np.testing.assert_allclose(saved.T_base_camera, result.T_base_camera)
    assert (dt.datetime.now(dt.UTC) - saved.timestamp).total_seconds() < 60
    # the quick check agrees with the calibration it just made
    poses = generate_calibration_poses(
        4,
        settings,
        result.T_base_camera,
        result.T_gripper_board,
        target.outline,
        np.random.default_rng(99),
        camera.intrinsics,
    )
    robot.refuse = None
    report = asyncio.run(
        check_calibration(robot, camera, settings, result.T_base_camera, result.T_gripper_board, poses)
    )
    assert report.ok, report.message


def test_pose_generator_keeps_the_board_in_view_and_spreads_rotations():
    settings = CalibrationSettings()
    target = CharucoTarget(settings.board)
    X = look_at_camera(np.array([0.45, 0.0, 0.0]), 0.8, 55.0)
    Y = default_T_gripper_board(target)
    intr = d435_intrinsics()
    poses = generate_calibration_poses(15, settings, X, Y, target.outline, np.random.default_rng(0), intr)
    assert len(poses) == 15
    rotvecs = []
    for G in poses:
        T_cb = invert_transform(X) @ G @ Y
        pc = target.outline @ T_cb[:3, :3].T + T_cb[:3, 3]
        u = intr.fx * pc[:, 0] / pc[:, 2] + intr.cx
        v = intr.fy * pc[:, 1] / pc[:, 2] + intr.cy
        assert np.all((u > 0) & (u < intr.width) & (v > 0) & (v < intr.height))
        assert T_cb[:3, 2] @ (T_cb[:3, :3] @ target.center_board + T_cb[:3, 3]) > 0  # printed side faces us
        rotvecs.append(Rotation.from_matrix(poses[0][:3, :3].T @ G[:3, :3]).as_rotvec())
    assert np.linalg.matrix_rank(np.array(rotvecs[1:]), tol=0.05) == 3
    far_away = settings.model_copy(update={"volume_min": (2.0, 2.0, 2.0), "volume_max": (2.1, 2.1, 2.1)})
    with pytest.raises(VisionError, match="camera's view"):
        generate_calibration_poses(5, far_away, X, Y, target.outline, np.random.default_rng(0), intr)
