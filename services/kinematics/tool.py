"""The one tool/TCP frame of the cell, built from settings, used by every service that reasons about it."""

from __future__ import annotations

import numpy as np

from services.common.settings import Settings
from services.kinematics.urdf import tool_geometry


def tool_frame(settings: Settings) -> np.ndarray:
    """``T_flange_tool``: the TCP ``gripper.tcp_offset_m`` along the flange z axis (the grasp centre), turned by
    ``motion.tool.tip_rpy_deg``. The driver's safety checks, grasp, motion, the task and the twin's scripted arm all
    take it from here, so a tip rotation means the same thing to each of them."""
    return tool_geometry(settings).T_flange_tool()
