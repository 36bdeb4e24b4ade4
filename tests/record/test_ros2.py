"""ROS 2 interop: with ``record.ros2_joint_states`` the recording also carries every joint state as
``sensor_msgs/msg/JointState`` (CDR, ``ros2msg`` schema), read back here with mcap-ros2-support's decoder
(what ROS 2 tools use), not with the writer's code."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from pickplace.v1 import common_pb2

from services.common.settings import load_settings
from services.record.channels import Topic
from services.record.service import Kind, RecordService

NAMES = [f"joint{i + 1}" for i in range(6)]


def joint_state(i: int) -> common_pb2.JointState:
    return common_pb2.JointState(
        header=common_pb2.Header(stamp_ns=1_700_000_000_000_000_000 + i, frame_id="base", seq=i),
        name=NAMES,
        position=[0.01 * i + k for k in range(6)],
        velocity=[0.1 * k for k in range(6)],
        effort=[-1.5 * k for k in range(6)],
        source_stamp_ns=5_000_000_000 + i * 8_000_000,  # the controller's clock, 125 Hz
    )


async def record(tmp_path: Path, ros2: bool, n: int) -> Path:
    s = load_settings("sim", overrides={"logging": {"file": None}, "record": {"ros2_joint_states": ros2}})
    svc = RecordService(s, None, live=False, record_dir=tmp_path)
    async with svc:
        for i in range(n):
            svc.submit(Kind.JOINTS, joint_state(i).SerializeToString(), wait=True)
    assert svc.recorder is not None
    (written,) = svc.recorder.files
    return written.path


def read(path: Path, topic: Topic) -> tuple[Any, list[Any]]:
    """The file's summary and the messages of ``topic``, decoded by mcap-ros2-support."""
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return reader.get_summary(), [m for _s, _c, _m, m in reader.iter_decoded_messages(topics=[topic])]


async def test_joint_states_are_recorded_as_ros2_sensor_msgs_joint_state(tmp_path: Path) -> None:
    summary, decoded = read(await record(tmp_path, True, 40), Topic.ROS2_JOINT_STATES)
    assert summary is not None
    (channel,) = [c for c in summary.channels.values() if c.topic == Topic.ROS2_JOINT_STATES]
    schema = summary.schemas[channel.schema_id]
    assert (schema.name, schema.encoding, channel.message_encoding) == (
        "sensor_msgs/msg/JointState",
        "ros2msg",
        "cdr",
    )
    assert len(decoded) == 40  # every state, none dropped
    for i, m in enumerate(decoded):
        js = joint_state(i)
        assert list(m.name) == NAMES and m.header.frame_id == "base"
        assert list(m.position) == pytest.approx(list(js.position))
        assert list(m.velocity) == pytest.approx(list(js.velocity))
        assert list(m.effort) == pytest.approx(list(js.effort))
        # stamped on the controller's clock, as the protobuf joint state's source stamp
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == js.source_stamp_ns


async def test_without_the_setting_no_ros2_joint_states_are_written(tmp_path: Path) -> None:
    summary, decoded = read(await record(tmp_path, False, 10), Topic.ROS2_JOINT_STATES)
    assert not decoded and summary is not None and summary.statistics is not None
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert counts[Topic.JOINT_STATES] == 10 and counts.get(Topic.ROS2_JOINT_STATES, 0) == 0
