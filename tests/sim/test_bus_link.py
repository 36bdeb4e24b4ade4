"""The simulated cell's process on Zenoh: its camera frames come at their period, or at once when asked."""

from __future__ import annotations

import asyncio
import os

import pytest
from pickplace.v1 import task_pb2, vision_pb2

from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.settings import Settings
from services.sim.app import build_sim_server
from services.sim.bus_link import SimBusLink
from tests.polling import until

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


async def test_periodic_frames_pause_while_a_cycle_runs(settings: Settings) -> None:
    """While the task says a cycle is under way the twin renders only the frames asked for (vision's
    Detect calls): its periodic renders took the CPU the cycle's planning waits for."""
    s = settings.model_copy(
        update={
            "sim": settings.sim.model_copy(
                update={"engine": "twin", "dashboard_port": 0, "feedback_port": 0, "slow_feedback_port": 0}
            )
        }
    )
    keys = CellKeys(s.cell_id)

    async def task_status(bus: Bus) -> None:
        while True:
            bus.publish(keys.task_status, task_pb2.TaskStatus(state="PLACE", cycle_active=True))
            await asyncio.sleep(0.1)

    async with build_sim_server(s) as server, Bus(s.zenoh) as bus:
        seqs: list[int] = []  # of the frames received, in order (appended on a Zenoh thread)
        sub = bus.subscribe_callback(
            keys.camera_frames, lambda _k, p: seqs.append(vision_pb2.RGBDFrame.FromString(p).header.seq)
        )
        async with SimBusLink(s, server, bus, frame_rate=20.0) as link:
            status = asyncio.create_task(task_status(bus))
            try:
                await until(lambda: link.paused_periods >= 1, "the periodic frames to pause")
                assert link.camera is not None
                rendered = link.camera._camera._seq  # the twin camera's frame count: none in flight now
                await until(lambda: rendered == 0 or rendered in seqs, "the last frame before the pause")
                await until(lambda: link.paused_periods >= 8, "more paused periods")
                assert link.camera._camera._seq == rendered  # nothing rendered while paused
                bus.publish(keys.camera_frame_requests, b"")
                await until(lambda: rendered + 1 in seqs, "the frame asked for")  # a Detect's frame still is
            finally:
                status.cancel()
        sub.undeclare()
