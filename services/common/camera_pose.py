"""Where the camera is: the calibration file's ``T_base_camera``, else the manual pose in the settings.

One reading of it for every service that needs the camera's pose (vision, the gateway's camera panel,
the recorder, the CLI), so they never disagree on where the camera is or which files are valid.
:mod:`services.vision.calibration` computes and writes the file; this module reads it.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from services.common.errors import ConfigurationError, InvalidInputError
from services.common.frames import check_transform, finite_vector, make_transform
from services.common.settings import REPO_ROOT, CalibrationSettings

Array = np.ndarray


def manual_T_base_camera(
    translation_m: Sequence[float],
    rpy_deg: Sequence[float] | None = None,
    quat_xyzw: Sequence[float] | None = None,
) -> Array:
    """T_base_camera from a measured camera position (m) and orientation (fixed-XYZ rpy in degrees, or xyzw).

    The orientation is of the camera's optical frame (z forward, x right, y down) in the base frame.
    """
    t = finite_vector(translation_m, 3, "camera translation")
    if np.linalg.norm(t) > 5.0:
        raise InvalidInputError(f"camera translation {t.tolist()} m is more than 5 m from the base: units?")
    if rpy_deg is not None and quat_xyzw is None:
        R = Rotation.from_euler("xyz", finite_vector(rpy_deg, 3, "camera rpy"), degrees=True).as_matrix()
    elif quat_xyzw is not None and rpy_deg is None:
        q = finite_vector(quat_xyzw, 4, "camera quaternion")
        if abs(np.linalg.norm(q) - 1.0) > 1e-3:
            raise InvalidInputError(f"camera quaternion must be unit length, |q| = {np.linalg.norm(q):.4f}")
        R = Rotation.from_quat(q).as_matrix()
    else:
        raise InvalidInputError("give exactly one of rpy_deg or quat_xyzw for the camera orientation")
    return check_transform(make_transform(R, t), "T_base_camera")


@dataclass(frozen=True)
class CalibrationFile:
    T_base_camera: Array
    timestamp: dt.datetime
    method: str
    record: dict[str, Any]


def read_calibration(path: str | Path) -> CalibrationFile:
    """Load and validate a calibration file; ConfigurationError says what is wrong."""
    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except FileNotFoundError as exc:
        raise ConfigurationError(
            f"no calibration file at {p}: run `pickplace calibrate` or set a manual pose"
        ) from exc
    except yaml.YAMLError as exc:
        raise ConfigurationError(f"calibration file {p} is not valid YAML: {exc}") from exc
    if not isinstance(data, dict) or "T_base_camera" not in data:
        raise ConfigurationError(f"calibration file {p} has no T_base_camera")
    try:
        T = check_transform(np.asarray(data["T_base_camera"], dtype=float), "T_base_camera")
    except (InvalidInputError, ValueError, TypeError) as exc:
        raise ConfigurationError(f"calibration file {p}: {exc}") from exc
    try:
        stamp = dt.datetime.fromisoformat(str(data.get("timestamp")))
    except ValueError as exc:
        raise ConfigurationError(
            f"calibration file {p} has no valid ISO timestamp: {data.get('timestamp')!r}"
        ) from exc
    return CalibrationFile(T_base_camera=T, timestamp=stamp, method=str(data.get("method", "")), record=data)


def load_T_base_camera(cal: CalibrationSettings) -> tuple[Array | None, str]:
    """(T_base_camera, where it came from): the calibration file, the manual pose, or nothing."""
    path = Path(cal.file)
    if not path.is_absolute():
        path = REPO_ROOT / path
    if path.exists():
        return read_calibration(path).T_base_camera, f"calibration file {path}"
    if cal.manual_translation_m is not None and cal.manual_rpy_deg is not None:
        return manual_T_base_camera(
            cal.manual_translation_m, rpy_deg=cal.manual_rpy_deg
        ), "manual pose in settings"
    return None, "none (camera-frame results only)"
