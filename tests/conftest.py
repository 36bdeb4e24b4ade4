"""Shared test fixtures: loopback only, free ports, the simulated Dobot."""

from __future__ import annotations

import os
from collections.abc import AsyncIterator

import numpy as np
import pytest
from hypothesis import settings as hypothesis_settings

os.environ.setdefault("MUJOCO_GL", "egl")

from services.common.net import free_loopback_port as free_port
from services.common.settings import Settings, load_settings

# Property tests draw the same examples on every run, so a red CI run is reproducible and a
# green one is not luck; HYPOTHESIS_PROFILE=explore draws new ones (and keeps what it finds).
hypothesis_settings.register_profile("repeatable", derandomize=True, database=None)
hypothesis_settings.register_profile("explore", derandomize=False)
hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


@pytest.fixture
def settings(tmp_path) -> Settings:  # type: ignore[no-untyped-def]
    """Sim-profile settings on free loopback ports, logging to the test's tmp dir."""
    zport = free_port()
    return load_settings(
        "sim",
        overrides={
            "logging": {"file": str(tmp_path / "pickplace.log")},
            "zenoh": {"listen": [f"tcp/127.0.0.1:{zport}"]},
            "grpc": {"robot_port": 0},
            "robot": {
                "retry_wait_s": 0.05,
                "request_timeout_s": 1.0,
                "motion_timeout_s": 20.0,
                "reconnect": {"max_attempts": 3, "base_delay_s": 0.05, "max_delay_s": 0.2},
            },
            "gripper": {"actuation_time_s": 0.05},
        },
    )


@pytest.fixture
async def sim_server(settings: Settings) -> AsyncIterator:  # type: ignore[type-arg]
    from services.sim.app import build_sim_server

    server = build_sim_server(settings, "kinematic", ports={"dashboard": 0, "feedback": 0, "slow": 0})
    async with server:
        yield server


@pytest.fixture
def robot_settings(settings: Settings, sim_server) -> Settings:  # type: ignore[no-untyped-def]
    """Settings whose robot points at the running sim."""
    r = settings.robot.model_copy(
        update={
            "dashboard_port": sim_server.ports["dashboard"],
            "feedback_port": sim_server.ports["feedback"],
        }
    )
    return settings.model_copy(update={"robot": r})


HOME = np.deg2rad([0.0, 0.0, 90.0, 0.0, -90.0, 0.0])
