"""The one tool/TCP frame of the cell, built from settings, used by every service that reasons about it: the
gripper's geometry on the flange (:class:`ToolGeometry`, which :mod:`services.kinematics.urdf` writes into the
URDF) and its TCP frame."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.errors import ConfigurationError
from services.common.settings import Settings

Array = np.ndarray

# What the tool's collision model leaves out above an object stood on the table: the open jaw's tips
# (``finger_clearance`` and the pad). A way past the object's top is planned this much higher, or the
# tips would catch it and knock it over (the task's placed object, the grasp's standing rod).
PLACED_TOP_CLEARANCE_M = 0.03


@dataclass(frozen=True)
class ToolGeometry:
    """The gripper on the flange, in the flange frame (m, rad).

    ``tip_xyz``/``tip_rpy``: the ``tool_tip`` frame (the TCP). The palm is a capsule
    along +z from the flange; the jaws are one box (open width along the tool y axis)
    ending ``finger_clearance`` short of the tip, so a grasp at the table surface
    does not count as a collision of the jaw tips.
    """

    tip_xyz: tuple[float, float, float] = (0.0, 0.0, 0.16)  # = the default gripper.tcp_offset_m
    tip_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    palm_radius: float = 0.045
    palm_length: float = 0.09
    finger_box: tuple[float, float, float] = (0.03, 0.12, 0.04)
    finger_clearance: float = 0.015

    def __post_init__(self) -> None:
        values = [
            *self.tip_xyz,
            *self.tip_rpy,
            self.palm_radius,
            self.palm_length,
            *self.finger_box,
            self.finger_clearance,
        ]
        if not all(np.isfinite(values)):
            raise ConfigurationError(f"tool geometry has non-finite values: {self}")
        if (
            self.palm_radius <= 0
            or self.palm_length < 0
            or min(self.finger_box) <= 0
            or self.finger_clearance < 0
        ):
            raise ConfigurationError(f"tool geometry sizes must be positive: {self}")

    def T_flange_tool(self) -> Array:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("xyz", self.tip_rpy).as_matrix()
        T[:3, 3] = self.tip_xyz
        return T

    def finger_center_z(self) -> float:
        return float(self.tip_xyz[2] - self.finger_clearance - self.finger_box[2] / 2)


def tool_geometry(settings: Settings) -> ToolGeometry:
    """The tool of ``settings``: TCP ``gripper.tcp_offset_m`` along the flange z, shapes from ``motion.tool``."""
    t = settings.motion.tool
    return ToolGeometry(
        tip_xyz=(0.0, 0.0, settings.gripper.tcp_offset_m),
        tip_rpy=tuple(math.radians(v) for v in t.tip_rpy_deg),  # type: ignore[arg-type]
        palm_radius=t.palm_radius_m,
        palm_length=t.palm_length_m,
        finger_box=t.finger_box_m,
        finger_clearance=t.finger_clearance_m,
    )


def tool_frame(settings: Settings) -> np.ndarray:
    """``T_flange_tool``: the TCP ``gripper.tcp_offset_m`` along the flange z axis (the grasp centre), turned by
    ``motion.tool.tip_rpy_deg``. The driver's safety checks, grasp, motion, the task and the twin's scripted arm all
    take it from here, so a tip rotation means the same thing to each of them."""
    return tool_geometry(settings).T_flange_tool()
