"""Live updates: the WebSocket carries joint states (decimated), task status and persisted picks.

Here the gateway runs its own Zenoh session connected to the cell's (as `pickplace serve gateway`
does), not a shared one.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import statistics
import time

import pytest
import websockets
from pickplace.v1 import task_pb2

from services.common.bus import Bus
from services.common.keys import CellKeys
from services.robot.service import RobotService
from tests.conftest import free_port
from tests.gateway.conftest import gateway_settings, migrate_up, pick_event, running_gateway

pytestmark = pytest.mark.integration


async def test_websocket_streams_decimated_joints_status_and_picks(
    robot_settings, sim_server, sqlite_db, tmp_path
):
    await migrate_up(sqlite_db)
    cell = gateway_settings(robot_settings, sqlite_db, tmp_path, joint_state_rate_hz=20.0)
    keys = CellKeys(cell.cell_id)
    async with Bus(cell.zenoh) as bus, RobotService(cell, bus, grpc_port=0) as robot:
        # the gateway's own session: connects to the cell's endpoint, listens on another
        zs = cell.zenoh.model_copy(
            update={"listen": [f"tcp/127.0.0.1:{free_port()}"], "connect": cell.zenoh.listen}
        )
        gs = cell.model_copy(
            update={"zenoh": zs, "grpc": cell.grpc.model_copy(update={"robot_port": robot.grpc_port})}
        )
        async with running_gateway(gs) as gw:
            url = gw.server.url.replace("http://", "ws://") + "/api/v1/live"
            async with websockets.connect(url) as ws:
                joints: list[dict] = []
                others: dict[str, list[dict]] = {}
                picks_sent = [pick_event(0), pick_event(1, success=False)]
                t0 = time.monotonic()
                published = False
                async with asyncio.timeout(15.0):
                    while time.monotonic() - t0 < 2.0 or "picks" not in others or "task_status" not in others:
                        if not published and time.monotonic() - t0 > 0.5:
                            # Zenoh subscriptions propagate between sessions asynchronously; publish once
                            # the joint states show that the gateway's session is connected
                            bus.publish(keys.task_status, task_pb2.TaskStatus(state="PLAN", progress=0.25))
                            for ev in picks_sent:
                                bus.publish(keys.pick_events, ev)
                            published = True
                        msg = json.loads(await ws.recv())
                        if msg["type"] == "joint_state":
                            joints.append(msg["data"])
                        else:
                            others.setdefault(msg["type"], []).append(msg["data"])
                elapsed = time.monotonic() - t0
    # Decimated on the controller's clock (the feedback TimeStamp each state carries): 125 Hz from the
    # driver, 20 Hz to the browser on a 50 ms schedule (the exact schedule is unit-tested in test_units).
    # Judged by the stamps, never by arrival times: at most one state per 50 ms slot, about 50 ms apart
    # (a busy simulator can skip feedback ticks, which moves single states within their slot).
    stamps = [j["source_stamp_ns"] for j in joints]
    gaps_ms = [(b - a) / 1e6 for a, b in itertools.pairwise(stamps)]
    assert len(joints) >= 10, f"only {len(joints)} joint states in {elapsed:.1f}s"
    assert all(g > 0 for g in gaps_ms), gaps_ms
    assert 40.0 <= statistics.median(gaps_ms) <= 80.0, gaps_ms
    # at most one state per 50 ms slot of the hub's schedule, which began before this connection's first
    # state: that one may sit anywhere in its slot, so the span covers at least len - 2 whole slots
    assert len(stamps) < (stamps[-1] - stamps[0]) / 50e6 + 2
    assert joints[-1]["name"][0] == "joint1" and abs(joints[-1]["position"][2] - 1.5707963) < 1e-5
    assert others["task_status"][-1]["state"] == "PLAN"
    got = [p for batch in others["picks"] for p in batch]
    assert sorted(p["pick_id"] for p in got) == sorted(e.pick_id for e in picks_sent)
    assert all(p["id"] >= 1 for p in got)  # database ids: sent after the rows were written
    assert "robot_status" in others and others["robot_status"][-1]["connected"] is True
