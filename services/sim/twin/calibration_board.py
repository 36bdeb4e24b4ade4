"""The ChArUco calibration board on the twin's gripper (``sim.twin.calibration_board``).

A thin textured plate fixed to the gripper body, printed face out beyond the fingertips (the
fingers would hide a board at the palm). Its pose in the flange frame is :func:`board_mount` — the
one definition the twin builds from and calibration runs in the twin pass as their board guess.

The plate is a 24-vertex box mesh (4 vertices per face, so the printed face keeps flat normals)
whose texture coordinates map the board image exactly onto the printed face: the board frame's
(x, y) = (u, v) · board size, as in :meth:`CharucoTarget.image`. The image goes to a PNG in a
cache directory at build time (MJCF textures load from files), named by its content.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np

from services.common.charuco import CharucoTarget, default_T_gripper_board
from services.common.errors import ConfigurationError
from services.common.settings import CalibrationBoardSettings, GripperSettings, Settings
from services.sim.twin import mjcf

Array = np.ndarray

BOARD_GEOM = "calibration_board"
BOARD_THICKNESS_M = 0.003
BOARD_CLEARANCE_M = 0.005  # printed face this far beyond the fingertips
BOARD_MASS_KG = 0.1
PX_PER_SQUARE = 80  # texture resolution: well above the ~30 px a square spans in the camera image

# The board faces the camera from ~0.18 m beyond the flange, so the wrist sits low: the board centre
# must stay high (z 0.30–0.42 m) and far enough out (x 0.55–0.72 m) for the camera (0.93, 0, 0.66)
# to see it. The arm starts on the elbow branch that reaches these poses without touching the table
# (nearest-IK from the default home would pick a branch through the table).
CALIBRATION_VOLUME_M = ((0.55, -0.12, 0.30), (0.72, 0.12, 0.42))
CALIBRATION_READY_DEG = (0.0, -40.0, -110.0, 0.0, -100.0, 0.0)


def board_standoff_m(gripper: GripperSettings) -> float:
    """Distance along the flange z axis from the flange to the board's printed face."""
    return gripper.tcp_offset_m + mjcf.PAD_HALF[2] + BOARD_CLEARANCE_M


def board_mount(board: CalibrationBoardSettings, gripper: GripperSettings) -> Array:
    """True T_gripper_board of the twin's board (gripper = flange frame, board = OpenCV board frame)."""
    return default_T_gripper_board(CharucoTarget(board), board_standoff_m(gripper))


def board_texture_png(target: CharucoTarget, cache_dir: Path | None = None) -> Path:
    """The board image as a PNG in ``cache_dir`` (default: the temp dir), written once per content."""
    image = target.image(PX_PER_SQUARE)
    ok, png = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - cv2 encodes any uint8 image
        raise RuntimeError("could not encode the calibration board image")
    data = png.tobytes()
    folder = cache_dir or Path(tempfile.gettempdir()) / "pickplace_twin"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"charuco_{hashlib.sha256(data).hexdigest()[:16]}.png"
    if not path.exists():
        # write-then-rename: concurrent builds never see half a file
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".png")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    return path


def _plate_mesh(size_m: tuple[float, float], T_gripper_board: Array) -> tuple[Array, Array, Array]:
    """(vertices in the gripper frame, texcoords, triangles) of the plate; faces wound outward."""
    w, h = size_m
    t = BOARD_THICKNESS_M
    corners = np.array([[x, y, z] for z in (0.0, t) for y in (0.0, h) for x in (0.0, w)])  # board frame
    center = corners.mean(axis=0)
    # Each face: 4 corner indices in cyclic order (index = x_bit + 2·y_bit + 4·z_bit).
    faces = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    verts: list[Array] = []
    uvs: list[tuple[float, float]] = []
    tris: list[tuple[int, int, int]] = []
    for face in faces:
        base = len(verts)
        for k in face:
            verts.append(corners[k])
            uvs.append((corners[k][0] / w, corners[k][1] / h))
        p = corners[list(face)]
        outward = p.mean(axis=0) - center
        for a, b, c in ((0, 1, 2), (0, 2, 3)):
            if np.cross(p[b] - p[a], p[c] - p[a]) @ outward < 0:
                b, c = c, b
            tris.append((base + a, base + b, base + c))
    v = np.asarray(verts) @ T_gripper_board[:3, :3].T + T_gripper_board[:3, 3]
    return v, np.asarray(uvs), np.asarray(tris)


def add_calibration_board(
    xml: str, board: CalibrationBoardSettings, gripper: GripperSettings, cache_dir: Path | None = None
) -> str:
    """``xml`` (from :func:`mjcf.build_mjcf`) with the board plate on the gripper body."""
    root = ET.fromstring(xml)
    target = CharucoTarget(board)
    asset = root.find("asset")
    body = root.find(f".//body[@name='{mjcf.GRIPPER_BODY}']")
    if asset is None or body is None:
        raise ConfigurationError("the cell MJCF has no <asset> or gripper body to hold the calibration board")
    png = board_texture_png(target, cache_dir)
    ET.SubElement(asset, "texture", name=BOARD_GEOM, type="2d", file=str(png))
    ET.SubElement(
        asset, "material", name=BOARD_GEOM, texture=BOARD_GEOM, specular="0", shininess="0", reflectance="0"
    )
    v, uv, tri = _plate_mesh(target.size_m, board_mount(board, gripper))
    ET.SubElement(
        asset,
        "mesh",
        name=BOARD_GEOM,
        vertex=mjcf._f(*v.ravel()),
        texcoord=mjcf._f(*uv.ravel()),
        face=" ".join(str(int(i)) for i in tri.ravel()),
    )
    ET.SubElement(
        body,
        "geom",
        name=BOARD_GEOM,
        type="mesh",
        mesh=BOARD_GEOM,
        material=BOARD_GEOM,
        mass=mjcf._f(BOARD_MASS_KG),
    )
    ET.indent(root)
    return ET.tostring(root, encoding="unicode")


def twin_calibration_settings(settings: Settings) -> Settings:
    """``settings`` set up for a calibration run in the twin: the table cleared (as for a real
    calibration), the board on, its true mount as the board guess (the solve still estimates it), the
    pose volume in the default camera's view, the arm in the ready posture."""
    board = settings.vision.calibration.board
    guess = board_mount(board, settings.gripper).tolist()
    lo, hi = CALIBRATION_VOLUME_M
    cal = settings.vision.calibration.model_copy(
        update={
            "board": board.model_copy(update={"T_gripper_board_guess": guess}),
            "volume_min": lo,
            "volume_max": hi,
        }
    )
    scene = settings.sim.twin.scene.model_copy(update={"rod": False, "cubes": [], "obstacle": False})
    twin = settings.sim.twin.model_copy(
        update={"calibration_board": True, "scene": scene, "initial_joints_deg": CALIBRATION_READY_DEG}
    )
    return settings.model_copy(
        update={
            "sim": settings.sim.model_copy(update={"twin": twin}),
            "vision": settings.vision.model_copy(update={"calibration": cal}),
        }
    )
