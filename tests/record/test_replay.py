"""Reading recordings back: bad files named with what is wrong, frames rebuilt, detections compared."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from pickplace.v1 import common_pb2, vision_pb2

from services.common.errors import InvalidInputError
from services.common.sensors import CameraIntrinsics
from services.common.settings import RecordSettings
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import ToolGeometry
from services.record import convert
from services.record.channels import Topic
from services.record.replay import Decoder, FrameAssembler, compare_detections, iter_messages, open_recording
from services.record.writer import Recorder


def small_recording(tmp_path: Path) -> Path:
    intr = CameraIntrinsics(width=32, height=24, fx=30.0, fy=30.0, cx=16.0, cy=12.0)
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:24, 0:32]
    color = np.stack([xx * 8, yy * 10, np.full_like(xx, 128)], axis=-1).astype(
        np.uint8
    )  # smooth: JPEG-friendly
    depth = rng.integers(300, 900, (24, 32)).astype(np.uint16)
    rec = Recorder(RecordSettings(), tmp_path)
    T = np.eye(4)
    T[:3, 3] = [0.9, 0.0, 0.6]
    links = convert.LinkTransforms(get_robot("nova5"), ToolGeometry(), T)
    rec.log(Topic.TF, links.message(np.zeros(6), 1), 1)
    for k in range(3):
        stamp = (k + 1) * 1_000_000_000
        rec.log(Topic.CAMERA_CALIBRATION, convert.camera_calibration(intr, stamp, "camera"), stamp)
        rec.log(Topic.CAMERA_COLOR, convert.color_jpeg(color, stamp, "camera", 95), stamp)
        rec.log(Topic.CAMERA_DEPTH, convert.depth_raw(depth + k, stamp, "camera"), stamp)
    rec.close()
    np.save(tmp_path / "color.npy", color)
    np.save(tmp_path / "depth.npy", depth)
    return rec.files[0].path


def test_frames_come_back_whole_with_the_recorded_calibration(tmp_path: Path) -> None:
    path = small_recording(tmp_path)
    info = open_recording(path)
    assert info.counts[Topic.CAMERA_COLOR] == 3 and info.schemas[Topic.TF] == "foxglove.FrameTransforms"
    assembler, decoder = FrameAssembler(), Decoder()
    frames = [f for m in iter_messages(path) if (f := assembler.add(m.topic, decoder.decode(m))) is not None]
    assert [f.stamp_ns for f in frames] == [1_000_000_000, 2_000_000_000, 3_000_000_000]
    depth = np.load(tmp_path / "depth.npy")
    assert np.array_equal(frames[2].depth, depth + 2)  # lossless
    assert np.abs(frames[0].color.astype(int) - np.load(tmp_path / "color.npy")).mean() < 6  # JPEG 95
    assert frames[0].intrinsics.fx == 30.0 and assembler.T_base_camera is not None
    assert np.allclose(assembler.T_base_camera[:3, 3], [0.9, 0.0, 0.6])


def test_a_truncated_file_is_named_and_called_truncated(tmp_path: Path) -> None:
    path = small_recording(tmp_path)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(InvalidInputError, match=r"cut\.mcap is truncated"):
        open_recording(cut)
    with pytest.raises(InvalidInputError, match=r"cut\.mcap is truncated"):
        list(iter_messages(cut))


def test_a_foreign_or_missing_file_is_named(tmp_path: Path) -> None:
    foreign = tmp_path / "notes.mcap"
    foreign.write_text("hello, this is not a recording\n")
    with pytest.raises(InvalidInputError, match=r"notes\.mcap is not an MCAP file"):
        open_recording(foreign)
    with pytest.raises(InvalidInputError, match=r"missing\.mcap: no such recording"):
        open_recording(tmp_path / "missing.mcap")


def test_a_corrupt_record_inside_is_a_corrupt_file(tmp_path: Path) -> None:
    path = small_recording(tmp_path)
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 64] = b"\xff" * 64
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    open_recording(bad)  # the summary at the end is intact ...
    with pytest.raises(InvalidInputError, match=r"bad\.mcap is a corrupt MCAP file: crc validation failed"):
        list(iter_messages(bad))  # ... the chunk's CRC is not


def _objs(
    rod: tuple[float, float, float] | None, cubes: list[tuple[str, float]]
) -> vision_pb2.DetectedObjects:
    o = vision_pb2.DetectedObjects(header=common_pb2.Header(stamp_ns=42))
    if rod is not None:
        o.rods.add(center_camera=vision_pb2.Vec3(x=rod[0], y=rod[1], z=rod[2]))
    for label, x in cubes:
        o.cubes.add(color_label=label, centroid_camera=vision_pb2.Vec3(x=x, y=0.0, z=0.8))
    return o


def test_detections_are_matched_by_kind_label_and_distance() -> None:
    recorded = _objs((0.0, 0.0, 0.8), [("red", 0.1), ("blue", -0.1)])
    same = compare_detections(recorded, _objs((0.002, 0.0, 0.8), [("blue", -0.101), ("red", 0.1)]))
    assert same.within(0.005) and same.worst_m == pytest.approx(0.002) and len(same.matched) == 3
    assert not same.within(0.001)
    changed = compare_detections(recorded, _objs(None, [("red", 0.1), ("green", -0.1)]))
    assert changed.missing == ["rod", "cube blue"] and changed.extra == ["cube green"]
    assert not changed.within(1.0)


async def test_replay_on_a_taken_port_says_which_and_what_to_do(tmp_path: Path) -> None:
    import socket

    from services.apps.record_cli import run_replay
    from services.common.errors import ConfigurationError
    from services.common.settings import load_settings

    path = small_recording(tmp_path)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        s = load_settings(
            "sim", overrides={"logging": {"file": None}, "record": {"foxglove": {"port": port}}}
        )
        with pytest.raises(ConfigurationError, match=f"127.0.0.1:{port}.*--foxglove-port"):
            await run_replay(s, path, fast=True, detect=False)


async def test_replay_at_recorded_speed_plays_every_message(tmp_path: Path) -> None:
    from rich.console import Console

    from services.apps.record_cli import run_replay
    from services.common.settings import load_settings

    path = small_recording(tmp_path)  # 2 s of frames: a paced replay sleeps through them
    s = load_settings("sim", overrides={"logging": {"file": None}, "record": {"foxglove": {"port": 0}}})
    report = await run_replay(s, path, fast=False, detect=True, out=Console(file=io.StringIO()))
    assert report.messages == sum(open_recording(path).counts.values()) and report.frames == 3
