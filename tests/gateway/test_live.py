"""Live updates: the WebSocket carries joint states (decimated), task status and persisted picks.

Here the gateway runs its own Zenoh session connected to the cell's (as `pickplace serve gateway`
does), not a shared one.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import statistics

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
                sent_ids = {e.pick_id for e in picks_sent}
                since_published: int | None = None

                def got_picks() -> set[str]:
                    return {p["pick_id"] for batch in others.get("picks", []) for p in batch}

                def span_s() -> float:  # controller time the joint states cover
                    return (
                        (joints[-1]["source_stamp_ns"] - joints[0]["source_stamp_ns"]) / 1e9
                        if joints
                        else 0.0
                    )

                async with asyncio.timeout(90.0):  # a safety net only: the loop ends on what it receives
                    while span_s() < 2.0 or got_picks() != sent_ids or "task_status" not in others:
                        msg = json.loads(await ws.recv())
                        if msg["type"] == "joint_state":
                            joints.append(msg["data"])
                        else:
                            others.setdefault(msg["type"], []).append(msg["data"])
                        # Zenoh subscriptions propagate between sessions asynchronously: publish once
                        # joint states show the gateway's session connected, and again every 10 states
                        # until both have come back (a pick is stored and reported once by its pick_id)
                        waiting = got_picks() != sent_ids or "task_status" not in others
                        if joints and waiting and (since_published is None or since_published >= 10):
                            bus.publish(keys.task_status, task_pb2.TaskStatus(state="PLAN", progress=0.25))
                            for ev in picks_sent:
                                bus.publish(keys.pick_events, ev)
                            since_published = 0
                        elif since_published is not None and msg["type"] == "joint_state":
                            since_published += 1
    # Decimated on the controller's clock (the feedback TimeStamp each state carries): 125 Hz from the
    # driver, 20 Hz to the browser on a 50 ms schedule (the exact schedule is unit-tested in test_units).
    # Judged by the stamps, never by arrival times: at most one state per 50 ms slot, about 50 ms apart
    # (a busy simulator slows its clock, which the stamps follow; a state Zenoh or the queue to this
    # client dropped moves the next one within its slot or leaves a slot empty, never fills one twice).
    stamps = [j["source_stamp_ns"] for j in joints]
    gaps_ms = [(b - a) / 1e6 for a, b in itertools.pairwise(stamps)]
    assert len(joints) >= 20, f"only {len(joints)} joint states in {span_s():.2f} s of the controller's clock"
    assert all(g > 0 for g in gaps_ms), gaps_ms
    assert 40.0 <= statistics.median(gaps_ms) <= 80.0, gaps_ms
    # at most one state per 50 ms slot of the hub's schedule, which began before this connection's first
    # state: that one may sit anywhere in its slot, so the span covers at least len - 2 whole slots
    assert len(stamps) < (stamps[-1] - stamps[0]) / 50e6 + 2
    assert joints[-1]["name"][0] == "joint1" and abs(joints[-1]["position"][2] - 1.5707963) < 1e-5
    assert others["task_status"][-1]["state"] == "PLAN"
    got = [p for batch in others["picks"] for p in batch]
    assert sorted(p["pick_id"] for p in got) == sorted(sent_ids)  # each reported once
    assert all(p["id"] >= 1 for p in got)  # database ids: sent after the rows were written
    assert "robot_status" in others and others["robot_status"][-1]["connected"] is True
