"""The simulated cell's process on Zenoh: its camera frames come at their period, or at once when asked."""

from __future__ import annotations

import asyncio
import os

import pytest
from pickplace.v1 import vision_pb2

from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.settings import Settings
from services.sim.app import build_sim_server
from services.sim.bus_link import SimBusLink

pytestmark = pytest.mark.integration

os.environ.setdefault("MUJOCO_GL", "egl")


async def test_a_frame_request_is_answered_before_the_period(settings: Settings) -> None:
    s = settings.model_copy(
        update={
            "sim": settings.sim.model_copy(
                update={"engine": "twin", "dashboard_port": 0, "feedback_port": 0, "slow_feedback_port": 0}
            )
        }
    )
    keys = CellKeys(s.cell_id)
    async with build_sim_server(s) as server, Bus(s.zenoh) as bus:
        frames = bus.subscribe(keys.camera_frames, vision_pb2.RGBDFrame)
        async with SimBusLink(s, server, bus, frame_rate=0.01):  # one frame per 100 s unless asked
            first = await frames.get(timeout_s=60.0)
            bus.publish(keys.camera_frame_requests, b"")
            second = await frames.get(timeout_s=60.0)  # 100 s early: only the request brings it
        frames.close()
    assert second.header.seq == first.header.seq + 1
    assert second.header.stamp_ns >= first.header.stamp_ns
