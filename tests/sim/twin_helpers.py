"""Shared helpers of the twin tests (no fixtures with state: each test builds what it mutates)."""

from __future__ import annotations

import os
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from services.common.frames import make_transform
from services.common.settings import Settings, load_settings

HOME = np.deg2rad([0.0, 0.0, 90.0, 0.0, -90.0, 0.0])


def twin_settings(
    scene: dict[str, Any] | None = None, physics: dict[str, Any] | None = None, **sections: Any
) -> Settings:
    """Sim settings with twin scene/physics overrides (e.g. ``{"cubes": [], "obstacle": False}``)."""
    twin: dict[str, Any] = {"scene": scene or {}, "physics": physics or {}}
    overrides: dict[str, Any] = {"sim": {"twin": twin}, "logging": {"file": None}, **sections}
    return load_settings("sim", overrides=overrides)


def top_down_tool(x: float, y: float, z: float, yaw: float = 0.0) -> np.ndarray:
    """T_base_tool pointing straight down, jaws closing along the base y axis rotated by ``yaw``."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    return make_transform(R, [x, y, z])
