"""The 1440-byte real-time feedback packet (port 30004): layout, encoding, decoding, stream framing."""

from __future__ import annotations

import numpy as np

from services.dobot.replies import ProtocolError

FEEDBACK_SIZE = 1440
TEST_VALUE = 0x0123456789ABCDEF

_F6 = ("<f8", (6,))
_FIELDS: list[tuple[str, object, int]] = [
    ("len", "<u2", 0),
    ("DigitalInputs", "<u8", 8),
    ("DigitalOutputs", "<u8", 16),
    ("RobotMode", "<u8", 24),
    ("TimeStamp", "<u8", 32),
    ("RunTime", "<u8", 40),
    ("TestValue", "<u8", 48),
    ("SpeedScaling", "<f8", 64),
    ("VRobot", "<f8", 88),
    ("IRobot", "<f8", 96),
    ("ProgramState", "<f8", 104),
    ("SafetyOIn", "<u2", 112),
    ("SafetyOOut", "<u2", 114),
    ("QTarget", _F6, 192),
    ("QDTarget", _F6, 240),
    ("QDDTarget", _F6, 288),
    ("ITarget", _F6, 336),
    ("MTarget", _F6, 384),
    ("QActual", _F6, 432),
    ("QDActual", _F6, 480),
    ("IActual", _F6, 528),
    ("ActualTCPForce", _F6, 576),
    ("ToolVectorActual", _F6, 624),
    ("TCPSpeedActual", _F6, 672),
    ("TCPForce", _F6, 720),
    ("ToolVectorTarget", _F6, 768),
    ("TCPSpeedTarget", _F6, 816),
    ("MotorTemperatures", _F6, 864),
    ("JointModes", _F6, 912),
    ("VActual", _F6, 960),
    ("HandType", ("i1", (4,)), 1008),
    ("User", "i1", 1012),
    ("Tool", "i1", 1013),
    ("RunQueuedCmd", "i1", 1014),
    ("PauseCmdFlag", "i1", 1015),
    ("VelocityRatio", "i1", 1016),
    ("AccelerationRatio", "i1", 1017),
    ("XYZVelocityRatio", "i1", 1019),
    ("RVelocityRatio", "i1", 1020),
    ("XYZAccelerationRatio", "i1", 1021),
    ("RAccelerationRatio", "i1", 1022),
    ("BrakeStatus", "i1", 1025),
    ("EnableStatus", "i1", 1026),
    ("DragStatus", "i1", 1027),
    ("RunningStatus", "i1", 1028),
    ("ErrorStatus", "i1", 1029),
    ("JogStatusCR", "i1", 1030),
    ("CRRobotType", "u1", 1031),
    ("SixForceOnline", "i1", 1037),
    ("CollisionState", "i1", 1038),
    ("VibrationDisZ", "<f8", 1104),
    ("CurrentCommandId", "<u8", 1112),
    ("MActual", _F6, 1120),
    ("Load", "<f8", 1168),
    ("CenterX", "<f8", 1176),
    ("CenterY", "<f8", 1184),
    ("CenterZ", "<f8", 1192),
    ("UserValue", _F6, 1200),
    ("ToolValue", _F6, 1248),
    ("SixForceValue", _F6, 1304),
    ("TargetQuaternion", ("<f8", (4,)), 1352),
    ("ActualQuaternion", ("<f8", (4,)), 1384),
    ("AutoManualMode", "<u2", 1416),
    ("ExportStatus", "<u2", 1418),
    ("SafetyState", "u1", 1420),
]

FEEDBACK_DTYPE = np.dtype(
    {
        "names": [f[0] for f in _FIELDS],
        "formats": [f[1] for f in _FIELDS],
        "offsets": [f[2] for f in _FIELDS],
        "itemsize": FEEDBACK_SIZE,
    }
)
assert FEEDBACK_DTYPE.itemsize == FEEDBACK_SIZE

_LEN_BYTES = FEEDBACK_SIZE.to_bytes(2, "little")
_TEST_BYTES = TEST_VALUE.to_bytes(8, "little")


def new_feedback() -> np.ndarray:
    """A zeroed packet record with the two sanity fields set."""
    rec = np.zeros((), dtype=FEEDBACK_DTYPE)
    rec["len"] = FEEDBACK_SIZE
    rec["TestValue"] = TEST_VALUE
    return rec


def encode_feedback(rec: np.ndarray) -> bytes:
    data = rec.tobytes()
    assert len(data) == FEEDBACK_SIZE
    return data


def decode_feedback(data: bytes) -> np.ndarray:
    if len(data) != FEEDBACK_SIZE:
        raise ProtocolError(f"feedback packet must be {FEEDBACK_SIZE} bytes, got {len(data)}")
    rec = np.frombuffer(data, dtype=FEEDBACK_DTYPE)[0]
    if int(rec["len"]) != FEEDBACK_SIZE or int(rec["TestValue"]) != TEST_VALUE:
        raise ProtocolError("feedback packet fails the len/TestValue check")
    return rec


def is_packet_start(buf: bytes | bytearray, i: int) -> bool:
    return buf[i : i + 2] == _LEN_BYTES and buf[i + 48 : i + 56] == _TEST_BYTES


class FeedbackFramer:
    """Turns the 30004 byte stream into packets, resynchronising on ``len`` + ``TestValue``
    after a partial read, a dropped byte or garbage (the ROS4 PR #23 fix)."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.resyncs = 0
        self.skipped_bytes = 0

    def _next_start(self, lo: int, hi: int) -> int:
        """First index in [lo, hi) where a complete header (len + TestValue) is, or -1."""
        idx = self._buf.find(_LEN_BYTES, lo, hi + 1)
        while 0 <= idx < hi:
            if len(self._buf) >= idx + 56 and is_packet_start(self._buf, idx):
                return idx
            idx = self._buf.find(_LEN_BYTES, idx + 1, hi + 1)
        return -1

    def feed(self, data: bytes) -> list[np.ndarray]:
        self._buf += data
        out: list[np.ndarray] = []
        while len(self._buf) >= FEEDBACK_SIZE:
            if is_packet_start(self._buf, 0):
                inner = self._next_start(1, FEEDBACK_SIZE)
                if inner < 0:
                    out.append(np.frombuffer(bytes(self._buf[:FEEDBACK_SIZE]), dtype=FEEDBACK_DTYPE)[0])
                    del self._buf[:FEEDBACK_SIZE]
                    continue
                # another header inside this one: the first packet was truncated, drop it
                self.resyncs += 1
                self.skipped_bytes += inner
                del self._buf[:inner]
                continue
            # search for the next plausible packet start
            idx = self._buf.find(_LEN_BYTES, 1)
            while idx >= 0 and len(self._buf) >= idx + 56 and not is_packet_start(self._buf, idx):
                idx = self._buf.find(_LEN_BYTES, idx + 1)
            self.resyncs += 1
            if idx < 0:
                keep = 1  # the last byte may be the first half of a len field
                self.skipped_bytes += len(self._buf) - keep
                del self._buf[: len(self._buf) - keep]
                break
            self.skipped_bytes += idx
            del self._buf[:idx]
        return out


# Plausibility bounds of a packet's values (beyond them a packet is corrupt, whatever the arm): no
# Dobot joint turns past ±360°, none moves at 1000 °/s, no TCP leaves a 5 m sphere, no wrist sensor
# reads 100 kN. Generous on purpose: they catch garbage and NaN, not a limit violation.
MAX_JOINT_DEG = 400.0
MAX_JOINT_SPEED_DEG_S = 1000.0
MAX_TCP_MM = 5000.0
MAX_FORCE = 1.0e5
# A clock that jumps forward more than this between two packets of one connection is garbage (the
# controller stamps every 8 ms; a reconnect starts a new baseline).
MAX_CLOCK_JUMP_MS = 3_600_000
_JOINT_FIELDS = ("QActual", "QTarget")
_VALID_MODES = frozenset(range(0, 12))  # 0: some firmware before INIT; beyond 11: none


def feedback_fault(rec: np.ndarray, prev_stamp_ms: int | None) -> str | None:
    """Why a decoded packet cannot be trusted (non-finite or implausible values the driver uses, a
    controller clock that runs backwards or leaps), or None when it is sound. Pure."""
    for name in _JOINT_FIELDS:
        v = np.asarray(rec[name], dtype=float)
        if not np.all(np.isfinite(v)):
            return f"{name} not finite"
        if np.any(np.abs(v) > MAX_JOINT_DEG):
            return f"{name} beyond ±{MAX_JOINT_DEG:.0f}°"
    qd = np.asarray(rec["QDActual"], dtype=float)
    if not np.all(np.isfinite(qd)):
        return "QDActual not finite"
    if np.any(np.abs(qd) > MAX_JOINT_SPEED_DEG_S):
        return f"QDActual beyond {MAX_JOINT_SPEED_DEG_S:.0f}°/s"
    tool = np.asarray(rec["ToolVectorActual"], dtype=float)
    if not np.all(np.isfinite(tool)):
        return "ToolVectorActual not finite"
    if np.any(np.abs(tool[:3]) > MAX_TCP_MM) or np.any(np.abs(tool[3:]) > MAX_JOINT_DEG):
        return "ToolVectorActual implausible"
    force = np.asarray(rec["ActualTCPForce"], dtype=float)
    if not np.all(np.isfinite(force)) or np.any(np.abs(force) > MAX_FORCE):
        return "ActualTCPForce not finite or implausible"
    if int(rec["RobotMode"]) not in _VALID_MODES:
        return f"RobotMode {int(rec['RobotMode'])} unknown"
    stamp = int(rec["TimeStamp"])
    if prev_stamp_ms is not None:
        if stamp < prev_stamp_ms:
            return f"controller clock ran backwards ({prev_stamp_ms} → {stamp} ms)"
        if stamp - prev_stamp_ms > MAX_CLOCK_JUMP_MS:
            return f"controller clock leapt {stamp - prev_stamp_ms} ms"
    return None
