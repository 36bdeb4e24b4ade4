"""A whole simulated cell (every service on loopback) for task tests."""

from __future__ import annotations

import pytest

from services.common.settings import Settings, deep_merge, load_settings
from tests.conftest import free_port


def cell_settings(tmp_path, **overrides) -> Settings:  # type: ignore[no-untyped-def]
    base = {
        "logging": {"file": str(tmp_path / "pickplace.log")},
        "zenoh": {"listen": [f"tcp/127.0.0.1:{free_port()}"]},
        "grpc": {"robot_port": 0, "motion_port": 0, "grasp_port": 0, "vision_port": 0, "task_port": 0},
        # the arm starts at the safe home, where every cycle starts (INIT moves it there otherwise)
        "sim": {
            "dashboard_port": 0,
            "feedback_port": 0,
            "slow_feedback_port": 0,
            "twin": {"initial_joints_deg": [180.0, 0.0, 90.0, 0.0, -90.0, 0.0]},
        },
        "task": {"detect_retry_delay_s": 0.05, "reset_scene_each_cycle": False},
        "record": {"foxglove": {"port": 0}},  # `pickplace up`'s live view on a free port, never 8765
        "state": {"dir": str(tmp_path / "state")},  # the task's cycle journal: this test's own
    }
    return load_settings("sim", overrides=deep_merge(base, overrides))


@pytest.fixture
def task_settings(tmp_path) -> Settings:  # type: ignore[no-untyped-def]
    return cell_settings(tmp_path)
