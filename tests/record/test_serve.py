"""``pickplace serve record``: the live view and recorder of a cell whose services run elsewhere, fed by Zenoh."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from pickplace.v1 import common_pb2, motion_pb2, task_pb2, vision_pb2

from services.apps.record_cli import serve_record
from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.sensors import CameraIntrinsics, RGBDFrame, frame_to_msg
from services.common.settings import load_settings
from services.record.channels import Topic
from tests.conftest import free_port
from tests.record.wsclient import FoxgloveClient

pytestmark = [pytest.mark.integration]


def recorded_counts(directory: Path) -> dict[str, int]:
    files = list(directory.glob("*.mcap"))
    assert len(files) == 1
    with files[0].open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    return {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}


PLAN = task_pb2.TaskPlan(
    cycle_index=4,
    label="APPROACH",
    tool_path=[common_pb2.Point(x=0.4, y=0.0, z=0.3), common_pb2.Point(x=0.45, y=0.1, z=0.2)],
    boxes=[motion_pb2.CollisionBox(name="obstacle0", x_min=0.3, x_max=0.4, y_min=-0.1, y_max=0.0, z_max=0.1)],
)


def decoded(directory: Path, topic: Topic) -> list[Any]:
    """The messages of ``topic`` in the one recording under ``directory``, decoded from its own schemas."""
    (path,) = directory.glob("*.mcap")
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [m for _s, _c, _m, m in reader.iter_decoded_messages(topics=[topic])]


async def connect(url: str) -> FoxgloveClient:
    """The server starts inside the service task: the first connection may find no listener yet."""
    async with asyncio.timeout(20):
        while True:
            try:
                return await FoxgloveClient(url).__aenter__()
            except OSError:
                await asyncio.sleep(0.05)  # a retry of a refused connection, not a wait on a state


async def test_serve_record_takes_the_cell_from_the_bus(tmp_path: Path) -> None:
    zport, fport = free_port(), free_port()
    s = load_settings(
        "sim",
        overrides={
            "logging": {"file": None},
            "zenoh": {"listen": [f"tcp/127.0.0.1:{zport}"]},
            "grpc": {"robot_port": free_port(), "request_timeout_s": 0.2},  # no robot there: status says so
            "record": {"dir": str(tmp_path), "foxglove": {"port": fport}, "camera_rate_hz": 100.0},
        },
    )
    keys = CellKeys(s.cell_id)
    task = asyncio.create_task(serve_record(s))
    peer = s.zenoh.model_copy(update={"listen": [f"tcp/127.0.0.1:{free_port()}"], "connect": s.zenoh.listen})
    try:
        async with Bus(peer) as bus:
            client = await connect(f"ws://127.0.0.1:{fport}")
            try:
                await client.wait_for_channels({Topic.JOINT_STATES, Topic.CAMERA_COLOR})
                await client.subscribe(
                    Topic.JOINT_STATES,
                    Topic.ROBOT_STATUS,
                    Topic.CAMERA_COLOR,
                    Topic.PLAN,
                    Topic.PLANNING_SCENE,
                )
                seq = 0

                def publish_state() -> None:
                    nonlocal seq
                    seq += 1
                    js = common_pb2.JointState(
                        header=common_pb2.Header(seq=seq), position=[0.01] * 6, robot_mode=5
                    )
                    bus.publish(keys.joint_states, js)

                async with asyncio.timeout(20):  # until the Zenoh subscription has reached this peer
                    while not client.count(Topic.JOINT_STATES):
                        publish_state()
                        try:
                            await client.wait_until(lambda: client.count(Topic.JOINT_STATES) > 0, 0.1)
                        except TimeoutError:
                            pass
                for _ in range(50):
                    publish_state()
                intr = CameraIntrinsics(width=16, height=12, fx=20.0, fy=20.0, cx=8.0, cy=6.0)
                frame = RGBDFrame(
                    np.full((12, 16, 3), 90, np.uint8),
                    np.full((12, 16), 700, np.uint16),
                    intr,
                    stamp_ns=123,
                    seq=1,
                )
                bus.publish(keys.camera_frames, frame_to_msg(frame))
                bus.publish(keys.detected_objects, vision_pb2.DetectedObjects())
                bus.publish(keys.task_plans, PLAN)  # as the task service of the cell publishes its plans
                await client.wait_until(
                    lambda: (
                        client.count(Topic.JOINT_STATES) >= 51
                        and client.count(Topic.ROBOT_STATUS) > 0
                        and client.count(Topic.CAMERA_COLOR) > 0
                        and client.count(Topic.PLAN) > 0
                        and client.count(Topic.PLANNING_SCENE) > 0
                    )
                )
            finally:
                await client.__aexit__(None, None, None)
    finally:
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
    status = [json.loads(p) for _t, p in client.received[Topic.ROBOT_STATUS]]
    assert any(not st["connected"] for st in status)  # the robot's gRPC is not there, and it says so
    counts = recorded_counts(tmp_path)
    # the recorder has every state the live client saw (and the first ones, before the client's subscription)
    assert seq >= counts[Topic.JOINT_STATES] >= client.count(Topic.JOINT_STATES) >= 51
    assert counts[Topic.CAMERA_COLOR] == 1 and counts[Topic.DETECTIONS] == 1
    # the task's plan: the tool path as a line and the boxes with the table, live and recorded (and as sent)
    assert counts[Topic.PLAN] == counts[Topic.PLANNING_SCENE] == counts[Topic.TASK_PLANS] == 1
    (plan,) = decoded(tmp_path, Topic.PLAN)
    assert [(p.x, p.y, p.z) for p in plan.entities[0].lines[0].points] == [(0.4, 0.0, 0.3), (0.45, 0.1, 0.2)]
    (planning_scene,) = decoded(tmp_path, Topic.PLANNING_SCENE)
    assert {e.id for e in planning_scene.entities} == {"table", "box:obstacle0"}
    (sent,) = decoded(tmp_path, Topic.TASK_PLANS)
    assert sent.cycle_index == 4 and sent.label == "APPROACH"
    assert client.received[Topic.PLAN][0][1] and client.received[Topic.PLANNING_SCENE][0][1]


async def test_a_taken_foxglove_port_is_a_configuration_error_naming_it(tmp_path: Path) -> None:
    import socket

    from services.common.errors import ConfigurationError
    from services.record.service import RecordService

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        s = load_settings(
            "sim", overrides={"logging": {"file": None}, "record": {"foxglove": {"port": port}}}
        )
        with pytest.raises(ConfigurationError, match=f"127.0.0.1:{port}.*--foxglove-port"):
            async with RecordService(s, None):
                pass


async def test_a_recording_whose_live_view_cannot_start_is_still_closed(tmp_path: Path) -> None:
    import socket

    from services.common.errors import ConfigurationError
    from services.record.replay import open_recording
    from services.record.service import RecordService

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        s = load_settings(
            "sim",
            overrides={"logging": {"file": None}, "record": {"foxglove": {"port": taken.getsockname()[1]}}},
        )
        svc = RecordService(s, None, record_dir=tmp_path)
        with pytest.raises(ConfigurationError):
            async with svc:
                pass
    assert svc.recorder is not None
    open_recording(svc.recorder.files[0].path)  # a whole file, footer and summary written
