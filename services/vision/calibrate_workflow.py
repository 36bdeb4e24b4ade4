"""The automatic eye-to-hand calibration run: poses → moves → board views → solve → file.

The robot and the camera come in through small protocols, so `pickplace
calibrate` can pass the Dobot driver client and any camera source, and tests
pass fakes (the twin is the end-to-end check). The pose generator and the
solve are pure; only :func:`collect_observations` awaits I/O.
"""

from __future__ import annotations

import asyncio
import datetime as dt
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.charuco import BoardObservation, CharucoTarget, default_T_gripper_board
from services.common.errors import InvalidInputError, RobotError, VisionError
from services.common.frames import check_transform, invert_transform, make_transform
from services.common.sensors import Camera, CameraIntrinsics
from services.common.settings import CalibrationSettings
from services.vision.calibration import (
    DriftReport,
    HandEyeResult,
    calibration_record,
    check_drift,
    reprojection_rms,
    solve_eye_to_hand,
    write_calibration,
)

Array = np.ndarray

Progress = Callable[[int, int, str], None]


@runtime_checkable
class CalibrationRobot(Protocol):
    """What calibration needs from the arm (poses of the gripper/flange frame in the base frame, metres)."""

    async def move_to_pose(self, T_base_gripper: Array) -> None:
        """Move (collision-checked, at a safe speed) and return when the arm has settled."""
        ...

    async def get_pose(self) -> Array:
        """The measured T_base_gripper now."""
        ...


def generate_calibration_poses(
    n: int,
    settings: CalibrationSettings,
    T_base_camera_guess: Array,
    T_gripper_board_guess: Array,
    board_corners: Array,
    rng: np.random.Generator,
    intrinsics: CameraIntrinsics | None = None,
    margin_px: int = 20,
) -> list[Array]:
    """N gripper poses (T_base_gripper) that show the board to the camera from varied angles.

    Board centres are spread through the configured safe volume (stratified along its longest
    axis); each board faces the camera, tilted by up to ``max_tilt_deg`` about a random axis and
    turned about its normal by up to ±30°, so the rotations span several axes (the solve needs that).
    With ``intrinsics``, poses whose board would leave the image (by the guessed camera pose) are
    drawn again. ``board_corners``: (K, 3) outline of the board in its own frame.
    """
    if n < 3:
        raise InvalidInputError(f"calibration needs at least 3 poses, got {n}")
    X = check_transform(T_base_camera_guess, "T_base_camera_guess")
    Y = check_transform(T_gripper_board_guess, "T_gripper_board_guess")
    corners = np.asarray(board_corners, dtype=float).reshape(-1, 3)
    center = corners.mean(axis=0)
    T_camera_base = invert_transform(X)
    lo, hi = np.asarray(settings.volume_min), np.asarray(settings.volume_max)
    cam = X[:3, 3]
    long_axis = int(np.argmax(hi - lo))
    poses = []
    for i in range(n):
        for _attempt in range(200):
            p = rng.uniform(lo, hi)
            p[long_axis] = lo[long_axis] + (i + rng.uniform(0.1, 0.9)) / n * (hi - lo)[long_axis]
            z_board = p - cam  # into the board = away from the camera
            z_board /= np.linalg.norm(z_board)
            tilt = Rotation.from_rotvec(
                _random_perpendicular(z_board, rng)
                * np.deg2rad(rng.uniform(0.3, 1.0) * settings.max_tilt_deg)
            )
            spin = Rotation.from_rotvec(z_board * np.deg2rad(rng.uniform(-30.0, 30.0)))
            R_face = _frame_with_z(z_board, X[:3, 1])  # board y roughly along the image's y
            R = (tilt * spin).as_matrix() @ R_face
            T_base_board = make_transform(R, p - R @ center)
            if intrinsics is None or _in_view(T_camera_base @ T_base_board, corners, intrinsics, margin_px):
                break
        else:
            raise VisionError(
                f"no calibration pose in the volume {lo.tolist()}–{hi.tolist()} m shows the whole board to the "
                "camera; move the volume into the camera's view"
            )
        poses.append(T_base_board @ invert_transform(Y))
    return poses


def _in_view(T_camera_board: Array, corners: Array, intr: CameraIntrinsics, margin: int) -> bool:
    pc = corners @ T_camera_board[:3, :3].T + T_camera_board[:3, 3]
    if np.any(pc[:, 2] <= 0.05):
        return False
    u = intr.fx * pc[:, 0] / pc[:, 2] + intr.cx
    v = intr.fy * pc[:, 1] / pc[:, 2] + intr.cy
    return bool(
        np.all((u >= margin) & (u <= intr.width - margin) & (v >= margin) & (v <= intr.height - margin))
    )


def _random_perpendicular(v: Array, rng: np.random.Generator) -> Array:
    a = np.cross(v, rng.normal(size=3))
    return a / np.linalg.norm(a)


def _frame_with_z(z: Array, y_hint: Array) -> Array:
    y = y_hint - (y_hint @ z) * z
    y /= np.linalg.norm(y)
    return np.column_stack([np.cross(y, z), y, z])


@dataclass
class CalibrationData:
    """What was collected: one entry per accepted pose, and why others were skipped."""

    T_base_gripper: list[Array] = field(default_factory=list)
    observations: list[BoardObservation] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)

    @property
    def T_camera_board(self) -> list[Array]:
        return [o.T_camera_board for o in self.observations]


async def collect_observations(
    robot: CalibrationRobot,
    camera: Camera,
    target: CharucoTarget,
    poses: Sequence[Array],
    settings: CalibrationSettings,
    progress: Progress | None = None,
) -> CalibrationData:
    """Visit each pose, read the robot's measured pose, grab a frame, detect the board."""
    data = CalibrationData()
    total = len(poses)
    for i, T in enumerate(poses, start=1):
        try:
            await robot.move_to_pose(T)
            G = check_transform(await robot.get_pose(), "measured T_base_gripper")
        except RobotError as exc:  # unreachable or refused: skip this pose, keep going
            data.skipped.append(f"pose {i}: robot could not reach it ({type(exc).__name__}: {exc})")
            _report(progress, i, total, data.skipped[-1])
            continue
        frame = await asyncio.to_thread(camera.capture)
        obs = target.detect(frame.color, frame.intrinsics, settings.min_board_corners)
        if obs is None:
            message = f"pose {i}: board not found (fewer than {settings.min_board_corners} corners)"
            data.skipped.append(message)
        elif obs.reprojection_rms_px > settings.max_reprojection_px:
            message = f"pose {i}: board pose unreliable (reprojection {obs.reprojection_rms_px:.2f} px)"
            data.skipped.append(message)
        else:
            data.T_base_gripper.append(G)
            data.observations.append(obs)
            message = f"pose {i}: {len(obs.ids)} corners, {obs.reprojection_rms_px:.2f} px"
        _report(progress, i, total, message)
    return data


def _report(progress: Progress | None, done: int, total: int, message: str) -> None:
    if progress is not None:
        progress(done, total, message)


def solve_from_observations(
    data: CalibrationData, camera_K: Array, distortion: Array | None = None
) -> HandEyeResult:
    """Hand-eye solve over the accepted views, with the reprojection residual filled in."""
    if len(data.observations) < 3:
        raise VisionError(
            f"only {len(data.observations)} usable board views (need ≥ 3); skipped: "
            + "; ".join(data.skipped[:5])
        )
    # every distinct corner seen: a stride through the stacked rows would pick one column of the
    # grid, a line, about which the board mount's rotation is unobservable
    corners = np.unique(np.round(np.vstack([o.object_points for o in data.observations]), 6), axis=0)
    result = solve_eye_to_hand(data.T_base_gripper, data.T_camera_board, board_points=corners)
    rms = reprojection_rms(
        result,
        data.T_base_gripper,
        [o.object_points for o in data.observations],
        [o.image_points for o in data.observations],
        camera_K,
        distortion,
    )
    return HandEyeResult(**{**result.__dict__, "reprojection_rms_px": rms})


async def run_calibration(
    robot: CalibrationRobot,
    camera: Camera,
    settings: CalibrationSettings,
    T_base_camera_guess: Array,
    out_path: str | Path | None = None,
    progress: Progress | None = None,
    seed: int = 0,
) -> tuple[HandEyeResult, CalibrationData]:
    """Generate poses, collect views, solve, and (if ``out_path``) write the calibration file."""
    target = CharucoTarget(settings.board)
    Y_guess = (
        np.asarray(settings.board.T_gripper_board_guess, dtype=float)
        if settings.board.T_gripper_board_guess is not None
        else default_T_gripper_board(target)
    )
    poses = generate_calibration_poses(
        settings.n_poses,
        settings,
        T_base_camera_guess,
        Y_guess,
        target.outline,
        np.random.default_rng(seed),
        camera.intrinsics,
    )
    data = await collect_observations(robot, camera, target, poses, settings, progress)
    intr = camera.intrinsics
    dist = np.asarray(intr.distortion, dtype=float) if intr.distortion else None
    result = solve_from_observations(data, intr.K, dist)
    if out_path is not None:
        record = calibration_record(
            result.T_base_camera, method=result.method, result=result, timestamp=dt.datetime.now(dt.UTC)
        )
        write_calibration(out_path, record)
    return result, data


async def check_calibration(
    robot: CalibrationRobot,
    camera: Camera,
    settings: CalibrationSettings,
    T_base_camera: Array,
    T_gripper_board: Array,
    poses: Sequence[Array],
    progress: Progress | None = None,
) -> DriftReport:
    """The quick check: a few poses, board seen vs where the robot says it is."""
    target = CharucoTarget(settings.board)
    data = await collect_observations(robot, camera, target, poses, settings, progress)
    if not data.observations:
        raise VisionError("drift check saw the board in none of the poses: " + "; ".join(data.skipped[:5]))
    return check_drift(
        T_base_camera,
        T_gripper_board,
        data.T_base_gripper,
        data.T_camera_board,
        settings.drift_warn_m,
        settings.drift_warn_deg,
    )
