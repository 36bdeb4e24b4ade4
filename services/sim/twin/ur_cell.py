"""The MuJoCo twin of a UR cell: the same scene, camera and parallel gripper as the Nova5's, built
from the UR5e/UR3 kinematics (``build_world`` reads ``robot.model``), behind the simulated UR
controller (:class:`services.sim.ur.controller.URController`) instead of the simulated Dobot.

The gripper sits on the flange's tool outputs (``gripper.tool_outputs``: UR tool DO 0 closes, DO 1
opens), which the UR controller hands to the twin in its engine convention (tool outputs from bit 32).
"""

from __future__ import annotations

from services.common.settings import Settings
from services.common.settings.robot import RobotDriverKind
from services.sim.twin.engine import TwinEngine, create_twin_engine

UR_MODELS = ("ur5e", "ur3")


def ur_cell_settings(settings: Settings, model: str) -> Settings:
    """``settings`` for a UR cell: the model, the UR driver and the gripper on the tool outputs."""
    if model not in UR_MODELS:
        raise ValueError(f"a UR cell is one of {UR_MODELS}, not {model!r}")
    robot = settings.robot.model_copy(update={"model": model, "driver": RobotDriverKind.UR_RTDE})
    gripper = settings.gripper.model_copy(update={"tool_outputs": True, "close_do": 1, "open_do": 2})
    return settings.model_copy(update={"robot": robot, "gripper": gripper})


def create_ur_twin_engine(settings: Settings, model: str, seed: int | None = None) -> TwinEngine:
    """The twin of the UR cell for ``settings`` (seeded scene); the arm starts at
    ``sim.twin.initial_joints_deg``."""
    return create_twin_engine(ur_cell_settings(settings, model), seed)
