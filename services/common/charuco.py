"""The ChArUco calibration board: definition, printable image, detection and pose (cv2.aruco + solvePnP).

Board frame (OpenCV's): origin at the board's outer top-left corner, x along
the squares' columns, y along the rows, z into the board; a camera facing the
printed side sees it with z pointing away.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from services.common.errors import ConfigurationError, InvalidInputError
from services.common.frames import make_transform
from services.common.sensors import CameraIntrinsics
from services.common.settings import CalibrationBoardSettings

Array = np.ndarray


@dataclass(frozen=True)
class BoardObservation:
    """One view of the board: its pose in the camera and the corners it was computed from."""

    T_camera_board: Array
    image_points: Array  # (N, 2) detected ChArUco corners (pixels)
    object_points: Array  # (N, 3) the same corners in the board frame (m)
    ids: Array  # (N,) corner ids
    reprojection_rms_px: float


class CharucoTarget:
    """A ChArUco board from settings, with detection and pose estimation."""

    def __init__(self, settings: CalibrationBoardSettings):
        name = settings.dictionary
        if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
            raise ConfigurationError(f"unknown ArUco dictionary {name!r} (e.g. DICT_5X5_100)")
        self.settings = settings
        self.dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
        n_markers = (settings.squares_x * settings.squares_y) // 2
        if n_markers > self.dictionary.bytesList.shape[0]:
            raise ConfigurationError(
                f"{settings.squares_x}x{settings.squares_y} board needs {n_markers} markers, "
                f"dictionary {name} has {self.dictionary.bytesList.shape[0]}"
            )
        self.board = cv2.aruco.CharucoBoard(
            (settings.squares_x, settings.squares_y),
            settings.square_length_m,
            settings.marker_length_m,
            self.dictionary,
        )
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.detector = cv2.aruco.CharucoDetector(self.board, cv2.aruco.CharucoParameters(), params)
        self.corners_board = np.asarray(self.board.getChessboardCorners(), dtype=float)

    @property
    def size_m(self) -> tuple[float, float]:
        s = self.settings
        return s.squares_x * s.square_length_m, s.squares_y * s.square_length_m

    @property
    def center_board(self) -> Array:
        w, h = self.size_m
        return np.array([w / 2, h / 2, 0.0])

    @property
    def outline(self) -> Array:
        """The board's four outer corners in its frame."""
        w, h = self.size_m
        return np.array([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, h, 0.0], [0.0, h, 0.0]])

    def image(self, px_per_square: int = 100) -> Array:
        """The printable board (uint8, white squares and markers, no margin)."""
        s = self.settings
        return self.board.generateImage(
            (s.squares_x * px_per_square, s.squares_y * px_per_square), marginSize=0, borderBits=1
        )

    def detect(self, image: Array, intr: CameraIntrinsics, min_corners: int = 6) -> BoardObservation | None:
        """Find the board and its pose; None when fewer than ``min_corners`` corners are seen."""
        if image.ndim == 3 and image.shape[2] == 3:
            gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        elif image.ndim == 2:
            gray = image
        else:
            raise InvalidInputError(f"board detection needs a grey or RGB image, got shape {image.shape}")
        if gray.dtype != np.uint8:
            raise InvalidInputError(f"board detection needs a uint8 image, got {gray.dtype}")
        intr.validate()
        corners, ids, _, _ = self.detector.detectBoard(gray)
        if ids is None or corners is None or len(ids) < max(min_corners, 4):
            return None
        ids = np.asarray(ids).reshape(-1)
        img_pts = np.asarray(corners, dtype=float).reshape(-1, 2)
        obj_pts = self.corners_board[ids]
        if self.board.checkCharucoCornersCollinear(ids.astype(np.int32).reshape(-1, 1)):
            return None
        dist = np.asarray(intr.distortion, dtype=float) if intr.distortion else None
        ok, rvec, tvec = cv2.solvePnP(obj_pts, img_pts, intr.K, dist, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            return None
        rvec, tvec = cv2.solvePnPRefineLM(obj_pts, img_pts, intr.K, dist, rvec, tvec)
        proj, _ = cv2.projectPoints(obj_pts, rvec, tvec, intr.K, dist)
        rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img_pts) ** 2, axis=1))))
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(rvec)[0]
        T[:3, 3] = tvec.ravel()
        return BoardObservation(
            T_camera_board=T, image_points=img_pts, object_points=obj_pts, ids=ids, reprojection_rms_px=rms
        )


def default_T_gripper_board(target: CharucoTarget, standoff_m: float = 0.02) -> Array:
    """A board on the flange facing along the tool z axis, centred ``standoff_m`` out (a guess only)."""
    R = Rotation.from_euler("x", 180, degrees=True).as_matrix()  # board z (into the board) = -tool z
    return make_transform(R, np.array([0.0, 0.0, standoff_m]) - R @ target.center_board)
