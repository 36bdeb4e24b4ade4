"""Reading a recording back: validation, messages in log-time order, camera frames rebuilt, detections compared.

Reads with the ``mcap`` reader (not the writer that wrote the file) and decodes every protobuf channel from
the schema embedded in the file (``mcap-protobuf-support``), so a file from another pickplace version still
decodes. Bad input is an :class:`~services.common.errors.InvalidInputError` naming the file and what is
wrong with it (not an MCAP file, cut off before it was closed, a corrupt record).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from google.protobuf.message import DecodeError
from mcap.exceptions import McapError
from mcap.reader import Summary, make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory
from pickplace.v1 import vision_pb2
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError
from services.common.sensors import CameraIntrinsics, RGBDFrame
from services.record.channels import Topic
from services.record.convert import BASE_FRAME

MAGIC = b"\x89MCAP0\r\n"


@dataclass(frozen=True)
class RecordedMessage:
    topic: str
    schema: Schema | None
    message_encoding: str
    log_time_ns: int
    data: bytes


@dataclass
class Recording:
    """A validated MCAP file: its channels (topic → schema name), message counts and time span."""

    path: Path
    summary: Summary
    schemas: dict[str, str]
    counts: dict[str, int]
    start_ns: int
    end_ns: int

    @property
    def duration_s(self) -> float:
        return max(self.end_ns - self.start_ns, 0) / 1e9


def _check_bytes(path: Path) -> None:
    if not path.is_file():
        raise InvalidInputError(f"{path}: no such recording (not a file)")
    size = path.stat().st_size
    with path.open("rb") as f:
        head = f.read(len(MAGIC))
        if head != MAGIC:
            raise InvalidInputError(
                f"{path} is not an MCAP file: it starts with {head!r}, not the MCAP magic"
            )
        f.seek(max(size - len(MAGIC), 0))
        tail = f.read(len(MAGIC))
    if size < 2 * len(MAGIC) or tail != MAGIC:
        raise InvalidInputError(
            f"{path} is truncated: {size} bytes without the closing MCAP footer (the recording was cut off "
            "before it was closed)"
        )


def open_recording(path: str | Path) -> Recording:
    """Validate ``path`` and read its summary (channels, schemas, statistics)."""
    p = Path(path)
    _check_bytes(p)
    try:
        with p.open("rb") as f:
            summary = make_reader(f).get_summary()
    except (McapError, ValueError, EOFError) as exc:
        raise InvalidInputError(f"{p} is a corrupt MCAP file: {exc}") from exc
    if summary is None or summary.statistics is None:
        raise InvalidInputError(
            f"{p} has no MCAP summary (no statistics to seek by): it was not closed cleanly"
        )
    schemas = {
        ch.topic: summary.schemas[ch.schema_id].name if ch.schema_id in summary.schemas else ""
        for ch in summary.channels.values()
    }
    counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
    st = summary.statistics
    return Recording(p, summary, schemas, counts, st.message_start_time, st.message_end_time)


def iter_messages(path: str | Path, topics: list[str] | None = None) -> Iterator[RecordedMessage]:
    """Every message of ``topics`` (None = all) in log-time order."""
    p = Path(path)
    _check_bytes(p)
    try:
        with p.open("rb") as f:
            for schema, channel, message in make_reader(f, validate_crcs=True).iter_messages(
                topics=topics, log_time_order=True
            ):
                yield RecordedMessage(
                    channel.topic, schema, channel.message_encoding, message.log_time, message.data
                )
    except Exception as exc:  # the reader's, the decompressors' and the CRC check's errors alike
        raise InvalidInputError(f"{p} is a corrupt MCAP file: {exc}") from exc


class Decoder:
    """Decodes protobuf messages with the schemas embedded in the file."""

    def __init__(self) -> None:
        self._factory = DecoderFactory()
        self._by_schema: dict[int, Any] = {}

    def decode(self, msg: RecordedMessage) -> Any:
        if msg.schema is None:
            raise InvalidInputError(f"message on {msg.topic} has no schema")
        fn = self._by_schema.get(msg.schema.id)
        if fn is None:
            fn = self._factory.decoder_for(msg.message_encoding, msg.schema)
            if fn is None:
                raise InvalidInputError(f"cannot decode {msg.message_encoding} messages on {msg.topic}")
            self._by_schema[msg.schema.id] = fn
        return fn(msg.data)


# ---------------------------------------------------------------------------- frames
def _ns(ts: Any) -> int:
    return int(ts.seconds) * 1_000_000_000 + int(ts.nanos)


@dataclass
class FrameAssembler:
    """Pairs /camera/color, /camera/depth and /camera/calibration of one capture (same timestamp) into an
    RGBDFrame; follows /tf for the camera's pose in the base frame (the calibration recorded)."""

    depth_scale: float = 0.001
    T_base_camera: np.ndarray | None = None
    _color: dict[int, np.ndarray] = field(default_factory=dict)
    _depth: dict[int, np.ndarray] = field(default_factory=dict)
    _intr: CameraIntrinsics | None = None
    _frame_id: str = "camera"

    def add(self, topic: str, msg: Any) -> RGBDFrame | None:
        if topic == Topic.CAMERA_CALIBRATION:
            K = list(msg.K)
            self._intr = CameraIntrinsics(
                width=int(msg.width),
                height=int(msg.height),
                fx=K[0],
                fy=K[4],
                cx=K[2],
                cy=K[5],
                distortion=tuple(float(d) for d in msg.D),
            )
            return None
        if topic == Topic.TF:
            for tf in msg.transforms:
                if tf.parent_frame_id == BASE_FRAME and tf.child_frame_id == self._frame_id:
                    T = np.eye(4)
                    r = tf.rotation
                    T[:3, :3] = Rotation.from_quat([r.x, r.y, r.z, r.w]).as_matrix()
                    T[:3, 3] = [tf.translation.x, tf.translation.y, tf.translation.z]
                    self.T_base_camera = T
            return None
        if topic == Topic.CAMERA_COLOR:
            bgr = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_COLOR)
            if bgr is None:
                raise InvalidInputError(f"a {msg.format} image on {topic} does not decode")
            stamp = _ns(msg.timestamp)
            self._frame_id = msg.frame_id or self._frame_id
            self._color[stamp] = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            return self._pop(stamp)
        if topic == Topic.CAMERA_DEPTH:
            if msg.encoding != "16UC1":
                raise InvalidInputError(f"depth on {topic} is {msg.encoding!r}, not 16UC1")
            stamp = _ns(msg.timestamp)
            depth = np.frombuffer(msg.data, dtype="<u2").reshape(int(msg.height), int(msg.width))
            self._depth[stamp] = depth.astype(np.uint16)
            return self._pop(stamp)
        return None

    def _pop(self, stamp: int) -> RGBDFrame | None:
        if stamp not in self._color or stamp not in self._depth or self._intr is None:
            return None
        color, depth = self._color.pop(stamp), self._depth.pop(stamp)
        for older in [s for s in (*self._color, *self._depth) if s < stamp]:  # unpaired halves: gone
            self._color.pop(older, None)
            self._depth.pop(older, None)
        return RGBDFrame(color, depth, self._intr, self.depth_scale, stamp, self._frame_id).validate()


# ---------------------------------------------------------------------------- comparison
def _v(p: Any) -> np.ndarray:
    return np.array([p.x, p.y, p.z], dtype=float)


@dataclass(frozen=True)
class Match:
    what: str
    distance_m: float


@dataclass
class DetectionComparison:
    """Recorded vs re-detected objects of one frame, matched nearest-first (camera frame, m)."""

    stamp_ns: int
    matched: list[Match] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)  # recorded, not found again
    extra: list[str] = field(default_factory=list)  # found again, not recorded

    @property
    def worst_m(self) -> float:
        return max((m.distance_m for m in self.matched), default=0.0)

    def within(self, tolerance_m: float) -> bool:
        return not self.missing and not self.extra and self.worst_m <= tolerance_m

    def describe(self) -> str:
        parts = [f"{len(self.matched)} matched (worst {1000 * self.worst_m:.1f} mm)"]
        if self.missing:
            parts.append(f"missing {self.missing}")
        if self.extra:
            parts.append(f"extra {self.extra}")
        return ", ".join(parts)


def _match(
    kind: str, rec: list[tuple[str, np.ndarray]], new: list[tuple[str, np.ndarray]], out: DetectionComparison
) -> None:
    pairs = sorted(
        (
            (float(np.linalg.norm(a - b)), i, j)
            for i, (la, a) in enumerate(rec)
            for j, (lb, b) in enumerate(new)
            if la == lb
        ),
    )
    used_r: set[int] = set()
    used_n: set[int] = set()
    for d, i, j in pairs:
        if i in used_r or j in used_n:
            continue
        used_r.add(i)
        used_n.add(j)
        out.matched.append(Match(f"{kind} {rec[i][0]}".strip(), d))
    out.missing += [f"{kind} {rec[i][0]}".strip() for i in range(len(rec)) if i not in used_r]
    out.extra += [f"{kind} {new[j][0]}".strip() for j in range(len(new)) if j not in used_n]


def compare_detections(
    recorded: vision_pb2.DetectedObjects, redetected: vision_pb2.DetectedObjects
) -> DetectionComparison:
    out = DetectionComparison(recorded.header.stamp_ns)
    _match(
        "rod",
        [("", _v(r.center_camera)) for r in recorded.rods],
        [("", _v(r.center_camera)) for r in redetected.rods],
        out,
    )
    _match(
        "cube",
        [(c.color_label, _v(c.centroid_camera)) for c in recorded.cubes],
        [(c.color_label, _v(c.centroid_camera)) for c in redetected.cubes],
        out,
    )

    def box(b: vision_pb2.ObstacleBox) -> tuple[str, np.ndarray]:
        return ("", (_v(b.camera.min) + _v(b.camera.max)) / 2)

    _match("obstacle", [box(b) for b in recorded.obstacles], [box(b) for b in redetected.obstacles], out)
    return out


def recorded_detections(path: str | Path) -> dict[int, vision_pb2.DetectedObjects]:
    """The recorded /vision/objects by the stamp of the frame they were detected on."""
    out: dict[int, vision_pb2.DetectedObjects] = {}
    for m in iter_messages(path, [Topic.VISION_OBJECTS]):
        try:
            objs = vision_pb2.DetectedObjects.FromString(m.data)
        except DecodeError as exc:
            raise InvalidInputError(
                f"{path}: a {Topic.VISION_OBJECTS} message does not decode: {exc}"
            ) from exc
        out[objs.header.stamp_ns] = objs
    return out
