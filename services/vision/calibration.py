"""Camera-to-base calibration of a fixed camera (eye-to-hand): manual and from board observations.

Unknowns: ``X = T_base_camera`` and ``Y = T_gripper_board`` (the board held by
the gripper). Each robot pose ``G_i = T_base_gripper_i`` with the board seen at
``C_i = T_camera_board_i`` gives ``G_i · Y = X · C_i``.

Solve: ``cv2.calibrateHandEye`` in its eye-to-hand form (pass the inverted
robot poses, base→gripper; its "cam2gripper" output is then cam→base = X).
The OpenCV 5.0.0 wheels do not expose that function (opencv/opencv#29565,
fixed upstream in #29584, not yet released), so when it is missing the same
closed-form method of Park & Martin (1994) — rotation from the log-maps of
relative motions by an SVD, translation by linear least squares — runs here.
Either way the result is then refined jointly for X and Y by nonlinear least
squares (scipy) on the board corners' 3D disagreement, which the closed forms
do not minimise.

Files: ``config/calibration.yaml`` holds ``T_base_camera`` with a timestamp,
the method, the residuals and the pose count; :func:`services.common.camera_pose.read_calibration`
validates it on load.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from services.common.errors import ConfigurationError, InvalidInputError, VisionError
from services.common.frames import check_transform, invert_transform, make_transform

Array = np.ndarray

CALIBRATION_FORMAT = 1
MIN_POSES = 3


# --- eye-to-hand solve --------------------------------------------------------------------------
@dataclass(frozen=True)
class HandEyeResult:
    T_base_camera: Array
    T_gripper_board: Array
    method: str
    n_poses: int
    translation_rms_m: float  # board position from robot vs camera, over the poses
    translation_max_m: float
    rotation_rms_deg: float
    rotation_max_deg: float
    reprojection_rms_px: float | None = None


def _rot_log(R: Array) -> Array:
    return Rotation.from_matrix(R).as_rotvec()


def _validate_pairs(
    T_base_gripper: Sequence[Array], T_camera_board: Sequence[Array]
) -> tuple[list[Array], list[Array]]:
    if len(T_base_gripper) != len(T_camera_board):
        raise InvalidInputError(
            f"need one board observation per robot pose, got {len(T_base_gripper)} poses and "
            f"{len(T_camera_board)} observations"
        )
    if len(T_base_gripper) < MIN_POSES:
        raise InvalidInputError(
            f"hand-eye calibration needs at least {MIN_POSES} poses, got {len(T_base_gripper)}"
        )
    G = [check_transform(T, f"T_base_gripper[{i}]") for i, T in enumerate(T_base_gripper)]
    C = [check_transform(T, f"T_camera_board[{i}]") for i, T in enumerate(T_camera_board)]
    return G, C


def _check_rotation_spread(G: list[Array]) -> None:
    """Two distinct rotation axes are needed; otherwise the solve is degenerate."""
    axes = []
    for i in range(1, len(G)):
        w = _rot_log(G[0][:3, :3].T @ G[i][:3, :3])
        if np.linalg.norm(w) > np.deg2rad(2.0):
            axes.append(w / np.linalg.norm(w))
    if len(axes) < 2 or np.linalg.matrix_rank(np.array(axes), tol=np.sin(np.deg2rad(5.0))) < 2:
        raise VisionError(
            "calibration poses do not rotate the gripper about at least two different axes by > 2°: "
            "the camera pose cannot be determined; spread the poses' orientations"
        )


def _park_martin(A: list[Array], B: list[Array]) -> Array:
    """Solve A_k X = X B_k (relative motions) in closed form (Park & Martin 1994)."""
    M = np.zeros((3, 3))
    for a, b in zip(A, B, strict=True):
        M += np.outer(_rot_log(b[:3, :3]), _rot_log(a[:3, :3]))
    # R = (MᵀM)^(-1/2) Mᵀ, via the SVD of M (and a det fix for noisy data)
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    lhs = np.vstack([a[:3, :3] - np.eye(3) for a in A])
    rhs = np.concatenate([R @ b[:3, 3] - a[:3, 3] for a, b in zip(A, B, strict=True)])
    t = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return make_transform(R, t)


def hand_eye_backends() -> list[str]:
    """Closed-form solvers available here ("opencv" only when cv2 exposes calibrateHandEye)."""
    return (["opencv"] if hasattr(cv2, "calibrateHandEye") else []) + ["park-martin"]


def _closed_form_X(G: list[Array], C: list[Array], backend: str) -> tuple[Array, str]:
    """Initial T_base_camera from cv2.calibrateHandEye (eye-to-hand inputs) or Park–Martin."""
    if backend == "auto":
        backend = hand_eye_backends()[0]
    if backend not in hand_eye_backends():
        raise ConfigurationError(
            f"hand-eye backend {backend!r} is not available here; use one of {hand_eye_backends()}"
        )
    if backend == "opencv":
        G_inv = [invert_transform(g) for g in G]  # eye-to-hand: base→gripper in place of gripper→base
        # not in every OpenCV build (hand_eye_backends() checks), nor in the stubs of this one
        R, t = cv2.calibrateHandEye(  # type: ignore[attr-defined, unused-ignore]
            [g[:3, :3] for g in G_inv],
            [g[:3, 3] for g in G_inv],
            [c[:3, :3] for c in C],
            [c[:3, 3] for c in C],
            method=cv2.CALIB_HAND_EYE_PARK,
        )
        return make_transform(R, np.ravel(t)), "cv2.calibrateHandEye(PARK)"
    # Y = G_i⁻¹ X C_i for every i, so for each pair (G_i G_j⁻¹) X = X (C_i C_j⁻¹): A X = X B.
    A, B = [], []
    for i in range(len(G)):
        for j in range(i + 1, len(G)):
            A.append(G[i] @ invert_transform(G[j]))
            B.append(C[i] @ invert_transform(C[j]))
    return _park_martin(A, B), "park-martin"


def _mean_transform(Ts: list[Array]) -> Array:
    R = Rotation.from_matrix(np.array([T[:3, :3] for T in Ts])).mean().as_matrix()
    return make_transform(R, np.mean([T[:3, 3] for T in Ts], axis=0))


def _pose_vec(T: Array) -> Array:
    return np.concatenate([_rot_log(T[:3, :3]), T[:3, 3]])


def _vec_pose(v: Array) -> Array:
    return make_transform(Rotation.from_rotvec(v[:3]).as_matrix(), v[3:])


def board_disagreement(X: Array, Y: Array, G: list[Array], C: list[Array]) -> tuple[Array, Array]:
    """Per pose: board position (m) and rotation (deg) from the robot (G·Y) vs from the camera (X·C)."""
    dt_m, dr_deg = [], []
    for g, c in zip(G, C, strict=True):
        robot = g @ Y
        camera = X @ c
        dt_m.append(np.linalg.norm(robot[:3, 3] - camera[:3, 3]))
        dr_deg.append(np.rad2deg(np.linalg.norm(_rot_log(robot[:3, :3].T @ camera[:3, :3]))))
    return np.array(dt_m), np.array(dr_deg)


def solve_eye_to_hand(
    T_base_gripper: Sequence[Array],
    T_camera_board: Sequence[Array],
    board_points: Array | None = None,
    refine: bool = True,
    backend: str = "auto",
) -> HandEyeResult:
    """T_base_camera (and T_gripper_board) from N ≥ 3 robot poses with the board seen in each.

    ``board_points``: (K, 3) points on the board (board frame) whose 3D disagreement the refinement
    minimises; default the corners of a 0.2 m square. ``backend``: "auto", "opencv" or "park-martin".
    """
    G, C = _validate_pairs(T_base_gripper, T_camera_board)
    _check_rotation_spread(G)
    X, method = _closed_form_X(G, C, backend)
    Y = _mean_transform([invert_transform(g) @ X @ c for g, c in zip(G, C, strict=True)])
    if refine:
        pts = (
            np.array([[0, 0, 0], [0.2, 0, 0], [0, 0.2, 0], [0.2, 0.2, 0]], float)
            if board_points is None
            else np.asarray(board_points, dtype=float).reshape(-1, 3)
        )
        if (
            not np.all(np.isfinite(pts))
            or len(pts) < 3
            or np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)[1] < 1e-3 * max(np.ptp(pts), 1e-9)
        ):
            raise InvalidInputError(
                "board_points must be ≥ 3 finite points spanning a plane: on a line, the board mount's "
                "rotation about that line is unobservable"
            )
        ph = np.column_stack([pts, np.ones(len(pts))]).T  # (4, K)

        # Refine small corrections about the closed-form start, not absolute rotation vectors: a
        # board mount turned 180° (the usual "face out" mount) sits on the rotation vector's
        # singularity, where the solver drifts (seen: the mount off by up to 6.6° run to run).
        X0, Y0 = X, Y

        def residuals(v: Array) -> Array:
            Xv, Yv = X0 @ _vec_pose(v[:6]), Y0 @ _vec_pose(v[6:])
            return np.concatenate(
                [((g @ Yv) @ ph - (Xv @ c) @ ph)[:3].ravel() for g, c in zip(G, C, strict=True)]
            )

        sol = least_squares(residuals, np.zeros(12), method="lm")
        X, Y = X0 @ _vec_pose(sol.x[:6]), Y0 @ _vec_pose(sol.x[6:])
        method += "+refined"
    X = check_transform(X, "T_base_camera")
    d_t, d_r = board_disagreement(X, Y, G, C)
    return HandEyeResult(
        T_base_camera=X,
        T_gripper_board=Y,
        method=method,
        n_poses=len(G),
        translation_rms_m=float(np.sqrt(np.mean(d_t**2))),
        translation_max_m=float(d_t.max()),
        rotation_rms_deg=float(np.sqrt(np.mean(d_r**2))),
        rotation_max_deg=float(d_r.max()),
    )


def reprojection_rms(
    result: HandEyeResult,
    T_base_gripper: Sequence[Array],
    object_points: Sequence[Array],
    image_points: Sequence[Array],
    K: Array,
    distortion: Array | None = None,
) -> float:
    """RMS pixel error of the board corners predicted from the robot poses through the calibration."""
    T_camera_base = invert_transform(result.T_base_camera)
    sq, n = 0.0, 0
    for g, obj, img in zip(T_base_gripper, object_points, image_points, strict=True):
        T = T_camera_base @ g @ result.T_gripper_board
        rvec = cv2.Rodrigues(T[:3, :3])[0]
        proj, _ = cv2.projectPoints(np.asarray(obj, float), rvec, T[:3, 3], K, distortion)
        sq += float(np.sum((proj.reshape(-1, 2) - np.asarray(img, float)) ** 2))
        n += len(obj)
    return float(np.sqrt(sq / max(n, 1)))


# --- drift check ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class DriftReport:
    translation_m: Array  # per pose
    rotation_deg: Array
    max_translation_m: float
    max_rotation_deg: float
    ok: bool
    message: str


def check_drift(
    T_base_camera: Array,
    T_gripper_board: Array,
    T_base_gripper: Sequence[Array],
    T_camera_board: Sequence[Array],
    warn_m: float = 0.005,
    warn_deg: float = 1.0,
) -> DriftReport:
    """Compare where the board is seen (through the calibration) with where the robot says it is."""
    if len(T_base_gripper) == 0 or len(T_base_gripper) != len(T_camera_board):
        raise InvalidInputError(
            f"drift check needs matching, non-empty pose and observation lists "
            f"({len(T_base_gripper)} vs {len(T_camera_board)})"
        )
    X = check_transform(T_base_camera, "T_base_camera")
    Y = check_transform(T_gripper_board, "T_gripper_board")
    G = [check_transform(T, f"T_base_gripper[{i}]") for i, T in enumerate(T_base_gripper)]
    C = [check_transform(T, f"T_camera_board[{i}]") for i, T in enumerate(T_camera_board)]
    d_t, d_r = board_disagreement(X, Y, G, C)
    ok = bool(d_t.max() <= warn_m and d_r.max() <= warn_deg)
    msg = (
        f"calibration holds: board within {d_t.max() * 1000:.1f} mm / {d_r.max():.2f}° of the robot's pose"
        if ok
        else f"calibration drifted: board seen {d_t.max() * 1000:.1f} mm / {d_r.max():.2f}° from where the robot "
        f"holds it (limits {warn_m * 1000:.1f} mm / {warn_deg:.2f}°): recalibrate"
    )
    return DriftReport(d_t, d_r, float(d_t.max()), float(d_r.max()), ok, msg)


# --- calibration file -------------------------------------------------------------------------------
def calibration_record(
    T_base_camera: Array,
    *,
    method: str,
    timestamp: dt.datetime | None = None,
    result: HandEyeResult | None = None,
    notes: str = "",
) -> dict[str, Any]:
    """The YAML-ready dict of a calibration (pure: the caller writes it)."""
    T = check_transform(T_base_camera, "T_base_camera")
    stamp = (timestamp or dt.datetime.now(dt.UTC)).astimezone(dt.UTC)
    rec: dict[str, Any] = {
        "format": CALIBRATION_FORMAT,
        "type": "hand_eye",
        "timestamp": stamp.isoformat(),
        "method": method,
        "T_base_camera": [[float(v) for v in row] for row in T],
        "translation_m": [float(v) for v in T[:3, 3]],
        "quaternion_xyzw": [float(v) for v in Rotation.from_matrix(T[:3, :3]).as_quat()],
        "rpy_deg": [float(v) for v in Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)],
    }
    if result is not None:
        rec["n_poses"] = result.n_poses
        rec["T_gripper_board"] = [[float(v) for v in row] for row in result.T_gripper_board]
        rec["residuals"] = {
            "translation_rms_m": result.translation_rms_m,
            "translation_max_m": result.translation_max_m,
            "rotation_rms_deg": result.rotation_rms_deg,
            "rotation_max_deg": result.rotation_max_deg,
            "reprojection_rms_px": result.reprojection_rms_px,
        }
    if notes:
        rec["notes"] = notes
    return rec


def write_calibration(path: str | Path, record: dict[str, Any]) -> Path:
    """Write atomically (temp file + rename) so a crash never leaves half a calibration."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_suffix(p.suffix + ".tmp")
    header = "# pickplace camera calibration (T_base_camera maps camera points to base points; metres)\n"
    tmp.write_text(header + yaml.safe_dump(record, sort_keys=False))
    tmp.replace(p)
    return p
