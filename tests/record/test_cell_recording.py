"""One twin pick cycle with the live view and the recorder on, as ``pickplace up`` wires them.

A Foxglove WebSocket client watches the cycle; the MCAP files are read back with the ``mcap`` reader; a
second recorder on a disk that fills up stops with an event while the cell finishes its cycle; the
recording is replayed into the vision pipeline and reproduces the recorded detections.
"""

from __future__ import annotations

import errno
import io
import json
import logging
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from pickplace.v1 import common_pb2, task_pb2
from rich.console import Console

from services.apps.cell import Cell
from services.apps.record_cli import FRAME_TOPICS, cell_live_view, run_replay
from services.common.keys import CellKeys
from services.common.modes import TaskKind
from services.record.channels import Topic
from services.record.replay import Decoder, FrameAssembler, iter_messages
from services.record.service import RecordService
from services.record.writer import RecordingStopped
from tests.apps.conftest import cell_settings
from tests.conftest import free_port
from tests.gateway.conftest import wait_until
from tests.record.wsclient import FoxgloveClient

pytestmark = [pytest.mark.integration, pytest.mark.slow]

CAMERA_RATE_HZ = 2.0
FEEDBACK_PERIOD_NS = 8_000_000  # the controller's 125 Hz


class FullDisk(io.BytesIO):
    def write(self, data) -> int:  # type: ignore[no-untyped-def, override]
        if self.tell() + len(data) > 50_000:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)


def decoder(advertised: dict):  # type: ignore[no-untyped-def, type-arg]
    """Decodes a channel's messages from the schema the server advertised (base64 FileDescriptorSet)."""
    import base64

    from mcap.records import Schema

    data = base64.b64decode(advertised["schema"])
    schema = Schema(id=1, name=advertised["schemaName"], encoding="protobuf", data=data)
    fn = DecoderFactory().decoder_for("protobuf", schema)
    assert fn is not None
    return fn


def read_mcap(path: Path):  # type: ignore[no-untyped-def]
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = [(c.topic, m.log_time, m.data) for _s, c, m in reader.iter_messages(log_time_order=True)]
    return summary, messages


async def test_a_twin_cycle_is_live_in_foxglove_and_recorded_and_replays(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="pickplace.record")
    rec_dir = tmp_path / "rec"
    s = cell_settings(
        tmp_path,
        state={"dir": str(tmp_path / "state")},  # its own: no cycle journal another run left behind
        # wall-clock compute deadlines as a safety net only: a loaded machine must not end the cycle at DETECT
        task={"detect_deadline_s": 120.0, "plan_deadline_s": 120.0},
        record={
            "dir": str(rec_dir),
            "camera_rate_hz": CAMERA_RATE_HZ,
            "foxglove": {"port": free_port(), "robot_status_period_s": 0.5},
        },
    )
    stopped: list[RecordingStopped] = []
    out = io.StringIO()
    published: list[int] = []  # the seq of every joint state the driver published while the test listened
    async with Cell(s, seed=3) as cell, cell_live_view(cell, Console(file=out)) as view:
        assert view is not None and view.live and view.recorder is not None
        heard = cell.bus.subscribe_callback(
            CellKeys(cell.settings.cell_id).joint_states,
            lambda _k, p: published.append(common_pb2.JointState.FromString(p).header.seq),
        )
        full = RecordService(
            cell.settings,
            cell.bus,
            live=False,
            record_dir=tmp_path / "full",
            opener=lambda p: FullDisk(),  # type: ignore[arg-type, return-value]
            on_stopped=stopped.append,
        )
        async with full, FoxgloveClient(f"ws://127.0.0.1:{view.port}") as client:
            await client.wait_for_channels(set(map(str, Topic)))
            assert client.server_info["op"] == "serverInfo"
            assert {t: client.channels[t]["schemaName"] for t in (Topic.TF, Topic.JOINT_STATES)} == {
                Topic.TF: "foxglove.FrameTransforms",
                Topic.JOINT_STATES: "pickplace.v1.JointState",
            }
            await client.subscribe(
                Topic.JOINT_STATES,
                Topic.TF,
                Topic.CAMERA_COLOR,
                Topic.ROBOT_DESCRIPTION,
                Topic.ROBOT_STATUS,
                Topic.LOG,
                Topic.PLAN,
                Topic.PLANNING_SCENE,
            )
            outcome = await cell.task.runner.run_cycle(TaskKind.STAND_ROD)  # type: ignore[union-attr]
            await cell.settle(0.5)  # the last states and the pick event reach the view
        heard.undeclare()
        # a state the test heard last may still be on its way into the recorder (another subscriber of the
        # same bus): leave only once the recorder has taken it, or stopping the recorder could drop it
        last = max(published)
        await wait_until(
            lambda: view.last_joint_seq >= last, 60.0, f"the recorder to take joint state {last}"
        )
    # the cell carried on through the full disk: the cycle ran to its outcome (its success is
    # test_cell's business; here the arm must have moved and the outcome must have been published)
    assert outcome.stage_reached not in ("INIT", "DETECT", "PLAN"), outcome.failure_reason
    assert "record" not in outcome.failure_reason.lower()

    # --- live: ≥ 100 joint states within one second of motion, counted on the controller's clock
    states = [common_pb2.JointState.FromString(p) for _t, p in client.received[Topic.JOINT_STATES]]
    moving = [js for js in states if np.max(np.abs(js.velocity)) > 0.05]
    assert moving, "the arm moved"
    t0 = moving[0].source_stamp_ns
    in_first_second = [js for js in states if t0 <= js.source_stamp_ns < t0 + 1_000_000_000]
    assert len(in_first_second) >= 100, len(in_first_second)
    assert len(client.received.get(Topic.TF, [])) >= 100
    assert client.received.get(Topic.CAMERA_COLOR), "camera frames live"
    assert b"<robot" in client.received[Topic.ROBOT_DESCRIPTION][0][1]
    status = [json.loads(p) for _t, p in client.received[Topic.ROBOT_STATUS]]
    assert {"RUNNING", "ENABLE"} & {st["mode_name"] for st in status} and all(
        st["connected"] for st in status
    )
    # the full disk's error event shows in the live log as well
    assert any(b"recording stopped" in p and b"No space left" in p for _t, p in client.received[Topic.LOG])
    # the plans of the cycle as tool-path lines, and the scene motion planned them in (table, obstacle box)
    decode = {t: decoder(client.channels[t]) for t in (Topic.PLAN, Topic.PLANNING_SCENE)}
    plans = [decode[Topic.PLAN](p) for _t, p in client.received[Topic.PLAN]]
    assert plans and all(len(u.entities[0].lines[0].points) >= 2 for u in plans)
    lo, hi = np.array(cell.settings.robot.workspace.min), np.array(cell.settings.robot.workspace.max)
    for u in plans:
        pts = np.array([(p.x, p.y, p.z) for p in u.entities[0].lines[0].points])
        assert np.all(pts >= lo - 1e-6) and np.all(pts <= hi + 1e-6)  # tool tip paths inside the workspace
    scenes = [decode[Topic.PLANNING_SCENE](p) for _t, p in client.received[Topic.PLANNING_SCENE]]
    ids = {e.id for u in scenes for e in u.entities}
    assert "table" in ids and any(i.startswith("box:obstacle") for i in ids)  # the twin scene has an obstacle

    # --- the full disk: an event naming the file and the cause; the cell finished its cycle regardless
    assert len(stopped) == 1 and "No space left" in stopped[0].reason
    assert str(stopped[0].path).startswith(str(tmp_path / "full"))

    # --- recording, read back with the mcap reader
    files = sorted(rec_dir.glob("*.mcap"))
    assert files == [f.path for f in view.recorder.files] and len(files) == 1
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith(f"recorded {rec_dir}")]
    assert len(lines) == 1 and str(files[0]) in lines[0]  # a line per file in the session log
    summary, messages = read_mcap(files[0])
    assert summary is not None and summary.chunk_indexes and summary.statistics is not None
    schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schemas[Topic.JOINT_STATES] == "pickplace.v1.JointState"
    assert schemas[Topic.CAMERA_COLOR] == "foxglove.CompressedImage"
    assert schemas[Topic.DETECTIONS] == "foxglove.SceneUpdate"
    assert {
        Topic.TF,
        Topic.TASK_STATUS,
        Topic.PICK_EVENTS,
        Topic.VISION_OBJECTS,
        Topic.LOG,
        Topic.ROBOT_DESCRIPTION,
    } <= set(schemas)
    by_topic: dict[str, list[bytes]] = {}
    for topic, _t, data in messages:
        by_topic.setdefault(topic, []).append(data)
    # every joint state published while the test listened is in the recording, in order, and they come
    # at ≈ 125 Hz of the controller's clock (a feedback reconnect on a loaded machine may leave a gap)
    js = [common_pb2.JointState.FromString(d) for d in by_topic[Topic.JOINT_STATES]]
    seqs = [m.header.seq for m in js]
    missing = sorted(set(published) - set(seqs))
    assert seqs == sorted(seqs) and len(published) > 100 and not missing, (
        f"joint states published but not recorded: {missing[:10]}; recorded {seqs[0]}..{seqs[-1]}, the "
        f"recorder took up to {view.last_joint_seq}, counted {view.recorder.files[0].messages} messages, "
        f"the file holds {len(messages)} ({summary.statistics.message_count} by its statistics)"
    )
    span = js[-1].source_stamp_ns - js[0].source_stamp_ns
    assert len(js) >= 0.8 * (span / FEEDBACK_PERIOD_NS + 1)
    # the task's plans of the cycle came over the bus (the task service publishes them), with the cycle's index
    sent = [task_pb2.TaskPlan.FromString(d) for d in by_topic[Topic.TASK_PLANS]]
    assert sent and {p.cycle_index for p in sent} == {1} and len(sent) == len(by_topic[Topic.PLAN])
    # every pick event, once
    picks = [task_pb2.PickEvent.FromString(d) for d in by_topic[Topic.PICK_EVENTS]]
    assert [p.pick_id for p in picks] == [outcome.pick_id]
    # frames at the configured rate: recorded capture stamps at least 1/rate apart
    images = []
    with files[0].open("rb") as f:
        for _s, _c, _m, decoded in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            topics=[Topic.CAMERA_COLOR]
        ):
            images.append(decoded.timestamp.seconds * 10**9 + decoded.timestamp.nanos)
    gaps = np.diff(images)
    assert len(images) >= 2 and np.all(gaps >= 1e9 / CAMERA_RATE_HZ - 1)
    assert summary.statistics.channel_message_counts

    # --- replay into Foxglove and the vision pipeline: the recorded detections come back
    port = free_port()
    seen_port: list[int] = []
    report = await run_replay(
        cell.settings.model_copy(
            update={
                "record": cell.settings.record.model_copy(
                    update={"foxglove": s.record.foxglove.model_copy(update={"port": port})}
                )
            }
        ),
        files[0],
        fast=True,
        tolerance_m=0.01,
        out=Console(file=io.StringIO()),
        on_server=seen_port.append,
    )
    assert seen_port == [port]
    assert report.messages == summary.statistics.message_count
    assert report.comparisons, "recorded frames with their recorded detections"
    assert report.ok, [c.describe() for c in report.comparisons]
    # /tf names the camera as its images do (it named it "camera": a replay pairs them by that name and
    # found the camera's pose only when such a /tf came before the first image by chance, otherwise it
    # detected without it and found one obstacle more than the cell)
    with files[0].open("rb") as f:
        decoded = [
            (c.topic, m)
            for _s, c, _m, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=[Topic.TF, Topic.CAMERA_COLOR]
            )
        ]
    image_frames = {m.frame_id for topic, m in decoded if topic == Topic.CAMERA_COLOR}
    tf_children = {tf.child_frame_id for topic, m in decoded if topic == Topic.TF for tf in m.transforms}
    assert image_frames and image_frames <= tf_children, (image_frames, sorted(tf_children))
    # and every frame the replay assembled had the camera's pose
    assembler, frame_decoder, posed = FrameAssembler(), Decoder(), []
    for m in iter_messages(files[0]):
        if m.topic in FRAME_TOPICS and assembler.add(m.topic, frame_decoder.decode(m)) is not None:
            posed.append(assembler.T_base_camera is not None)
    assert posed and all(posed), posed
