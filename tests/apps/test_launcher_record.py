"""``pickplace up --processes --record DIR``: the recorder is one of the launcher's processes.

The topology adds ``pickplace serve record`` (after the gateway, with the run's Foxglove port) only when the
run records. Then the real command runs as the launcher's child on the launcher's Zenoh router: a peer
publishes the cell's streams (joint states, a plan of the task), a Foxglove client sees them live, and once
the launcher has stopped the child (SIGTERM) its MCAP file is whole and holds them, read with the ``mcap``
reader.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from mcap.reader import make_reader
from pickplace.v1 import common_pb2, motion_pb2, task_pb2

from services.apps.launcher import Launcher
from services.apps.topology import RECORD, SERVICES, LocalPorts, topology
from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.settings import load_settings
from services.record.channels import Topic
from tests.record.wsclient import FoxgloveClient

TOKEN = "record-test-token-0123456789"


def test_the_recorder_is_a_process_of_the_run_only_when_it_records(tmp_path: Path) -> None:
    ports = LocalPorts.free()
    plain = topology(load_settings("sim"), ports, api_token=TOKEN)
    assert [s.name for s in plain] == list(SERVICES)
    s = load_settings("sim", overrides={"record": {"dir": str(tmp_path)}})
    specs = topology(s, ports, api_token=TOKEN, metrics_root=tmp_path / "m", log_dir=tmp_path / "l")
    assert [sp.name for sp in specs] == [*SERVICES, RECORD]  # started last, stopped first
    rec = specs[-1]
    assert rec.args == ("serve", "record") and rec.metrics_port is None
    assert rec.env["PICKPLACE_RECORD__DIR"] == str(tmp_path)
    assert rec.env["PICKPLACE_RECORD__FOXGLOVE__ENABLED"] == "true"
    assert rec.env["PICKPLACE_RECORD__FOXGLOVE__PORT"] == str(ports.foxglove)
    assert rec.env["PICKPLACE_GATEWAY__API_TOKEN"] == TOKEN  # its robot-status calls carry the cell's token
    quiet = load_settings("sim", overrides={"record": {"dir": str(tmp_path), "foxglove": {"enabled": False}}})
    (rec,) = [sp for sp in topology(quiet, ports, api_token=TOKEN) if sp.name == RECORD]
    assert rec.env["PICKPLACE_RECORD__FOXGLOVE__ENABLED"] == "false"
    assert "PICKPLACE_RECORD__FOXGLOVE__PORT" not in rec.env


@pytest.mark.integration
@pytest.mark.timeout(300)
async def test_the_launchers_record_process_shows_and_records_the_bus_and_closes_its_file(
    tmp_path: Path,
) -> None:
    rec_dir = tmp_path / "rec"
    s = load_settings(
        "sim",
        overrides={
            "logging": {"file": None},
            "record": {"dir": str(rec_dir)},
            "grpc": {"request_timeout_s": 0.5},  # no robot in this run: the status says so
        },
    )
    ports = LocalPorts.free()
    specs = [sp for sp in topology(s, ports, api_token=TOKEN, log_dir=tmp_path / "log") if sp.name == RECORD]
    keys = CellKeys(s.cell_id)
    peer = s.zenoh.model_copy(
        update={"mode": "client", "listen": [], "connect": [f"tcp/127.0.0.1:{ports.zenoh}"]}
    )
    seq = 0
    plan = task_pb2.TaskPlan(
        cycle_index=1,
        label="APPROACH",
        tool_path=[common_pb2.Point(x=0.4, y=0.0, z=0.3), common_pb2.Point(x=0.45, y=0.1, z=0.2)],
        boxes=[motion_pb2.CollisionBox(name="obstacle0", x_min=0.3, x_max=0.4, y_max=0.1, z_max=0.1)],
    )
    async with Launcher(s, specs, ports, log_dir=tmp_path / "log", stop_grace_s=30.0) as launcher:
        assert [e.kind for e in launcher.events if e.service == RECORD] == ["started", "healthy"]
        async with Bus(peer) as bus, FoxgloveClient(f"ws://127.0.0.1:{ports.foxglove}") as client:
            await client.wait_for_channels({Topic.JOINT_STATES, Topic.PLAN})
            await client.subscribe(Topic.JOINT_STATES, Topic.PLAN, Topic.PLANNING_SCENE)

            def publish_state() -> None:
                nonlocal seq
                seq += 1
                bus.publish(
                    keys.joint_states,
                    common_pb2.JointState(
                        header=common_pb2.Header(seq=seq), position=[0.02] * 6, robot_mode=5
                    ),
                )

            async with asyncio.timeout(60):  # until the record process's subscription reaches this client
                while not client.count(Topic.JOINT_STATES):
                    publish_state()
                    try:
                        await client.wait_until(lambda: client.count(Topic.JOINT_STATES) > 0, 0.2)
                    except TimeoutError:
                        pass
            for _ in range(20):
                publish_state()
            bus.publish(keys.task_plans, plan)
            await client.wait_until(
                lambda: client.count(Topic.JOINT_STATES) >= 21 and client.count(Topic.PLAN) > 0, 60
            )
        child = launcher.children[RECORD]
    assert child.proc is not None and child.proc.returncode == 0, child.proc and child.proc.returncode
    (path,) = rec_dir.glob("*.mcap")
    with path.open("rb") as f:  # the footer and summary are there: stopped by SIGTERM, closed in order
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert seq >= counts[Topic.JOINT_STATES] >= 21
    assert counts[Topic.PLAN] == counts[Topic.PLANNING_SCENE] == counts[Topic.TASK_PLANS] == 1
