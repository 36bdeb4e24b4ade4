"""MCAP files read back with the ``mcap`` reader: chunked, compressed, self-describing, split; a failing disk."""

from __future__ import annotations

import errno
import io
import logging
from pathlib import Path
from typing import BinaryIO

import pytest
from mcap.reader import make_reader
from pickplace.v1 import common_pb2, task_pb2

from services.common.settings import RecordSettings
from services.record.channels import Topic
from services.record.writer import Recorder, RecorderState, RecordingStopped


def joint_state(i: int) -> bytes:
    return common_pb2.JointState(
        header=common_pb2.Header(seq=i, stamp_ns=i * 8_000_000), position=[0.001 * i] * 6
    ).SerializeToString()


def read(path: Path):  # type: ignore[no-untyped-def]
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = [(c.topic, m.log_time) for _s, c, m in reader.iter_messages()]
    return summary, messages


def test_files_split_by_size_each_one_self_describing_and_indexed(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    settings = RecordSettings(max_file_bytes=16_384, chunk_bytes=4096)
    caplog.set_level(logging.INFO, logger="pickplace.record")
    rec = Recorder(
        settings,
        tmp_path,
        prefix="cell1",
        attachments={"nova5.urdf": ("application/xml", b"<robot/>")},
        latched={Topic.ROBOT_DESCRIPTION: b'{"data": "<robot/>"}'},
    )
    for i in range(2000):
        rec.log(Topic.JOINT_STATES, joint_state(i), 1_000 + i)
        if i % 500 == 0:
            rec.log(Topic.PICK_EVENTS, task_pb2.PickEvent(pick_id=f"p{i}").SerializeToString(), 1_000 + i)
    rec.close()
    assert rec.state is RecorderState.CLOSED
    paths = sorted(tmp_path.glob("cell1_*.mcap"))
    assert len(paths) >= 3 and paths == [f.path for f in rec.files]
    total = 0
    for path in paths:
        summary, messages = read(path)
        assert summary is not None and summary.statistics is not None
        assert summary.chunk_indexes, "chunked"
        assert {ci.compression for ci in summary.chunk_indexes} == {"zstd"}
        assert all(ci.message_index_length > 0 for ci in summary.chunk_indexes), "message indexes for seeking"
        by_topic = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        assert by_topic[Topic.JOINT_STATES].name == "pickplace.v1.JointState"
        assert by_topic[Topic.JOINT_STATES].encoding == "protobuf" and by_topic[Topic.JOINT_STATES].data
        assert [a.name for a in summary.attachment_indexes] == ["nova5.urdf"]
        assert summary.statistics.message_count == len(messages)
        assert sum(t == Topic.ROBOT_DESCRIPTION for t, _ in messages) == 1  # every file has the description
        total += len(messages)
    assert total == 2000 + 4 + len(paths)
    assert [f.bytes for f in rec.files] == [p.stat().st_size for p in paths]
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("recorded ")]
    assert len(lines) == len(paths) and all(str(p) in line for p, line in zip(paths, lines, strict=True))


def test_files_split_by_time(tmp_path: Path) -> None:
    now = [0]
    rec = Recorder(RecordSettings(max_file_s=1.0), tmp_path, clock_ns=lambda: now[0])
    for i in range(30):
        now[0] = i * 100_000_000  # 0.1 s apart on the injected clock
        rec.log(Topic.JOINT_STATES, joint_state(i), now[0])
    rec.close()
    counts = [len(read(f.path)[1]) for f in rec.files]
    assert sum(counts) == 30 and len(counts) == 3 and counts[0] == 10


class FullDisk(io.BytesIO):
    """A file system that takes ``room`` bytes, then answers ENOSPC."""

    def __init__(self, room: int):
        super().__init__()
        self.room = room

    def write(self, data) -> int:  # type: ignore[no-untyped-def, override]
        if self.tell() + len(data) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)


def test_a_full_disk_stops_the_recording_with_an_event_and_raises_nothing(tmp_path: Path) -> None:
    events: list[RecordingStopped] = []

    def opener(path: Path) -> BinaryIO:
        return FullDisk(room=6000)

    rec = Recorder(RecordSettings(chunk_bytes=2048), tmp_path, opener=opener, on_stopped=events.append)
    for i in range(3000):
        rec.log(Topic.JOINT_STATES, joint_state(i), i)  # never raises: the cell's loop goes on
    rec.close()
    assert rec.state is RecorderState.FAILED
    assert len(events) == 1 and events[0].path == rec.files[0].path
    assert "No space left" in events[0].reason


def test_a_directory_that_cannot_take_files_is_a_stopped_recording(tmp_path: Path) -> None:
    events: list[RecordingStopped] = []

    def opener(path: Path) -> BinaryIO:
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    rec = Recorder(RecordSettings(), tmp_path, opener=opener, on_stopped=events.append)
    rec.log(Topic.JOINT_STATES, joint_state(0), 0)
    assert rec.state is RecorderState.FAILED and "Permission denied" in events[0].reason
