"""The one TCP frame: every user of the tool frame takes it from ``tool_frame(settings)``."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.settings import Settings, load_settings
from services.kinematics.tool import tool_frame
from services.robot.service import build_driver
from services.task.clients import GrpcMotion


def _settings_with_a_turned_tip() -> Settings:
    return load_settings(
        "sim",
        overrides={"motion": {"tool": {"tip_rpy_deg": [0.0, 0.0, 90.0]}}, "gripper": {"tcp_offset_m": 0.2}},
    )


def test_tool_frame_is_the_tcp_offset_turned_by_the_tip_rotation() -> None:
    T = tool_frame(_settings_with_a_turned_tip())
    assert np.allclose(T[:3, 3], [0.0, 0.0, 0.2])
    assert np.allclose(T[:3, :3], Rotation.from_euler("z", 90, degrees=True).as_matrix())


def test_driver_safety_checks_and_the_task_use_the_same_tool_frame() -> None:
    # with a non-zero tip rotation, the driver's workspace check and the task's tool poses agree
    s = _settings_with_a_turned_tip()
    T = tool_frame(s)
    driver = build_driver(s)  # builds the client, connects nothing
    assert driver.limits.T_flange_tool is not None and np.array_equal(driver.limits.T_flange_tool, T)
    motion = GrpcMotion(stub=None, settings=s)  # type: ignore[arg-type]
    assert np.array_equal(motion._T_flange_tool, T)
