"""Dobot TCP/IP "V4" protocol, sans-I/O: command encoding, reply framing/parsing,
server-side command framing/parsing (for the simulator) and the enums of the manual.

Wire facts (shared/specs/dobot-v4-protocol-and-kinematics.md §2–3):
- a command is ``Name(p1,p2,...)`` with no terminator; names are case-insensitive;
- a reply is ``ErrorID,{values},<echo of the command>;`` with no newline;
- queue commands return their ResultID in ``{}`` (a client must accept ``{}``);
- floats are written like the SDK (``{:f}``, six decimals), ratios as integers.
"""

from __future__ import annotations

import enum
import json
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np


class RobotMode(enum.IntEnum):
    INIT = 1
    BRAKE_OPEN = 2
    POWER_OFF = 3
    DISABLED = 4
    ENABLE = 5  # enabled and idle
    BACKDRIVE = 6
    RUNNING = 7
    SINGLE_MOVE = 8
    ERROR = 9
    PAUSE = 10
    COLLISION = 11

    @classmethod
    def name_of(cls, value: int) -> str:
        try:
            return cls(value).name
        except ValueError:
            return f"UNKNOWN({value})"


class ErrorID(enum.IntEnum):
    OK = 0
    FAILED = -1
    ALARM = -2
    ESTOP = -3
    POWERED_OFF = -4
    SCRIPT_RUNNING = -5
    JOG_MISMATCH = -6
    SCRIPT_PAUSED = -7
    LICENCE = -8
    UNKNOWN_COMMAND = -10000
    PARAM_COUNT = -20000
    # -3000X type / -4000X range of required parameter X; -5000X / -6000X of optional ones
    REQUIRED_TYPE = -30000
    REQUIRED_RANGE = -40000
    OPTIONAL_TYPE = -50000
    OPTIONAL_RANGE = -60000


ERROR_ID_TEXT = {
    0: "accepted",
    -1: "received but failed to execute",
    -2: "robot is in alarm state (clear the alarm and resend)",
    -3: "robot is in emergency-stop state (release the e-stop, clear, resend)",
    -4: "robot is powered off",
    -5: "a script is running; command refused",
    -6: "jog axis and coordinate type mismatch",
    -7: "a script is paused; command refused",
    -8: "controller licence expired",
    -10000: "unknown command",
    -20000: "wrong number of parameters",
}


def describe_error_id(error_id: int) -> str:
    if error_id in ERROR_ID_TEXT:
        return ERROR_ID_TEXT[error_id]
    for base, what in (
        (-30000, "wrong type of required parameter"),
        (-40000, "required parameter out of range"),
        (-50000, "wrong type of optional parameter"),
        (-60000, "optional parameter out of range"),
    ):
        if base - 9 <= error_id <= base - 1:
            return f"{what} {base - error_id}"
    return f"error {error_id}"


class Alarm(enum.IntEnum):
    """Controller alarm IDs that motion code reacts to (GetErrorID)."""

    SHOULDER_SINGULARITY = 16
    IK_NO_SOLUTION = 17
    IK_OUT_OF_WORKSPACE = 18
    WRIST_SINGULARITY = 26
    ELBOW_SINGULARITY = 27
    SPEED_PARAMETER = 29
    FULL_IK_FAILED = 30
    ENABLE_FAILED = 115
    ESTOP_PRESSED = 116
    COLLISION = 117


ALARM_TEXT = {
    16: "planned point near the shoulder singularity",
    17: "inverse kinematics has no solution",
    18: "IK result out of the working area",
    26: "near the wrist singularity",
    27: "near the elbow singularity",
    29: "speed parameter wrong",
    30: "full-parameter IK failed",
    115: "enable failed",
    116: "emergency stop button pressed",
    117: "collision detected",
}


def joint_overspeed_alarm(joint_index: int) -> int:
    """48..53: joint 1..6 overspeed (joint_index 0-based)."""
    return 48 + joint_index


def joint_limit_alarm(joint_index: int, positive: bool) -> int:
    """64..75: J1 positive, J1 negative, ..., J6 negative (joint_index 0-based)."""
    return 64 + 2 * joint_index + (0 if positive else 1)


def describe_alarm(alarm_id: int) -> str:
    if alarm_id in ALARM_TEXT:
        return ALARM_TEXT[alarm_id]
    if 48 <= alarm_id <= 53:
        return f"joint {alarm_id - 47} overspeed"
    if 64 <= alarm_id <= 75:
        j, neg = divmod(alarm_id - 64, 2)
        return f"joint {j + 1} {'negative' if neg else 'positive'} limit"
    return f"alarm {alarm_id}"


# Commands the controller accepts while in alarm / e-stop state (DOC465 §5).
ALLOWED_IN_ERROR = frozenset(
    {"clearerror", "geterrorid", "emergencystop", "stop", "robotmode", "logexportusb", "getexportstatus"}
)

QUEUE_COMMANDS = frozenset(
    {
        "movj",
        "movl",
        "movjio",
        "movlio",
        "arc",
        "arcio",
        "circle",
        "servoj",
        "servop",
        "relmovjtool",
        "relmovltool",
        "relmovjuser",
        "relmovluser",
        "reljointmovj",
        "startpath",
        "movs",
        "do",
        "tooldo",
        "ao",
        "dogroup",
        "user",
        "tool",
        "setpayload",
        "setcollisionlevel",
        "setsafewallenable",
        "setbackdistance",
        "setpostcollisionmode",
        "enablesafeskin",
        "setsafeskin",
    }
)


# --------------------------------------------------------------------------- encoding
def fmt_float(v: float) -> str:
    """The SDK's six-decimal fixed format."""
    return f"{float(v):f}"


def fmt_int(v: int) -> str:
    if isinstance(v, bool) or int(v) != v:
        raise ValueError(f"integer parameter expected, got {v!r}")
    return f"{int(v):d}"


def fmt_point(values: Sequence[float]) -> str:
    return "{" + ",".join(fmt_float(v) for v in values) + "}"


def command(name: str, *args: str, **kwargs: str | None) -> str:
    """Assemble ``Name(a,b,k=v)``; keyword values that are None are left out."""
    parts = list(args) + [f"{k}={v}" for k, v in kwargs.items() if v is not None]
    return f"{name}({','.join(parts)})"


def _opt_int(v: int | None) -> str | None:
    return None if v is None else fmt_int(v)


def enable_robot(load_kg: float = 0.0) -> str:
    return command("EnableRobot", fmt_float(load_kg)) if load_kg else command("EnableRobot")


def mov_j_joint(
    q_deg: Sequence[float], a: int | None = None, v: int | None = None, cp: int | None = None
) -> str:
    return command("MovJ", f"joint={fmt_point(q_deg)}", a=_opt_int(a), v=_opt_int(v), cp=_opt_int(cp))


def mov_j_pose(
    pose_mm_deg: Sequence[float], a: int | None = None, v: int | None = None, cp: int | None = None
) -> str:
    return command("MovJ", f"pose={fmt_point(pose_mm_deg)}", a=_opt_int(a), v=_opt_int(v), cp=_opt_int(cp))


def _mov_l(target: str, a: int | None, v: int | None, speed: int | None, cp: int | None) -> str:
    # an absolute speed (mm/s) replaces the velocity ratio: the controller takes one or the other
    return command(
        "MovL",
        target,
        a=_opt_int(a),
        v=None if speed is not None else _opt_int(v),
        speed=_opt_int(speed),
        cp=_opt_int(cp),
    )


def mov_l_joint(
    q_deg: Sequence[float],
    a: int | None = None,
    v: int | None = None,
    speed: int | None = None,
    cp: int | None = None,
) -> str:
    return _mov_l(f"joint={fmt_point(q_deg)}", a, v, speed, cp)


def mov_l_pose(
    pose_mm_deg: Sequence[float],
    a: int | None = None,
    v: int | None = None,
    speed: int | None = None,
    cp: int | None = None,
) -> str:
    return _mov_l(f"pose={fmt_point(pose_mm_deg)}", a, v, speed, cp)


def servo_j(
    q_deg: Sequence[float],
    t_s: float | None = None,
    aheadtime: float | None = None,
    gain: float | None = None,
) -> str:
    return command(
        "ServoJ",
        *[fmt_float(x) for x in q_deg],
        t=None if t_s is None else fmt_float(t_s),
        aheadtime=None if aheadtime is None else fmt_float(aheadtime),
        gain=None if gain is None else fmt_float(gain),
    )


def rel_mov_j_tool(offset_mm_deg: Sequence[float], a: int | None = None, v: int | None = None) -> str:
    return command("RelMovJTool", *[fmt_float(x) for x in offset_mm_deg], a=_opt_int(a), v=_opt_int(v))


def rel_mov_l_tool(offset_mm_deg: Sequence[float], a: int | None = None, v: int | None = None) -> str:
    return command("RelMovLTool", *[fmt_float(x) for x in offset_mm_deg], a=_opt_int(a), v=_opt_int(v))


def rel_mov_j_user(offset_mm_deg: Sequence[float], a: int | None = None, v: int | None = None) -> str:
    return command("RelMovJUser", *[fmt_float(x) for x in offset_mm_deg], a=_opt_int(a), v=_opt_int(v))


def rel_mov_l_user(offset_mm_deg: Sequence[float], a: int | None = None, v: int | None = None) -> str:
    return command("RelMovLUser", *[fmt_float(x) for x in offset_mm_deg], a=_opt_int(a), v=_opt_int(v))


def rel_joint_mov_j(offset_deg: Sequence[float], a: int | None = None, v: int | None = None) -> str:
    return command("RelJointMovJ", *[fmt_float(x) for x in offset_deg], a=_opt_int(a), v=_opt_int(v))


def digital_output(index: int, on: bool, tool: bool = False) -> str:
    return command("ToolDO" if tool else "DO", fmt_int(index), "1" if on else "0")


def speed_factor(ratio: int) -> str:
    if not 1 <= int(ratio) <= 100:
        raise ValueError(f"speed ratio must be 1-100, got {ratio}")
    return command("SpeedFactor", fmt_int(ratio))


def acceleration_ratios(ratio: int) -> tuple[str, str]:
    """AccJ and AccL: the default acceleration percentage of joint and linear moves."""
    if not 1 <= int(ratio) <= 100:
        raise ValueError(f"acceleration ratio must be 1-100, got {ratio}")
    return command("AccJ", fmt_int(ratio)), command("AccL", fmt_int(ratio))


def emergency_stop(press: bool = True) -> str:
    return command("EmergencyStop", "1" if press else "0")


def positive_kin(q_deg: Sequence[float]) -> str:
    return command("PositiveKin", *[fmt_float(x) for x in q_deg])


def inverse_kin(pose_mm_deg: Sequence[float], joint_near_deg: Sequence[float] | None = None) -> str:
    args = [fmt_float(x) for x in pose_mm_deg]
    if joint_near_deg is None:
        return command("InverseKin", *args)
    return command("InverseKin", *args, useJointNear="1", jointNear=fmt_point(joint_near_deg))


# --------------------------------------------------------------------------- replies
@dataclass(frozen=True)
class Reply:
    error_id: int
    values_text: str  # text between the braces of the value field
    echo: str  # the command as the controller echoed it
    raw: str

    @property
    def ok(self) -> bool:
        return self.error_id == 0

    @property
    def command_name(self) -> str:
        return self.echo.split("(", 1)[0].strip()

    def values(self) -> list[str]:
        text = self.values_text.strip()
        return [t.strip() for t in text.split(",")] if text else []

    def floats(self) -> list[float]:
        try:
            return [float(t) for t in self.values()]
        except ValueError as exc:
            raise ProtocolError(f"non-numeric values in reply {self.raw!r}") from exc

    @property
    def result_id(self) -> int | None:
        """The queue ResultID, or None when the controller returned ``{}``."""
        vals = self.values()
        if len(vals) != 1:
            return None
        try:
            return int(vals[0])
        except ValueError:
            return None


@dataclass(frozen=True)
class Unparseable:
    """Bytes that are not a well-formed reply (logged and reported, never fatal to the stream)."""

    text: str
    reason: str


class ProtocolError(ValueError):
    pass


_REPLY_HEAD = re.compile(r"\s*(-?\d+)\s*,\s*\{")


def _scan_balanced(text: str, start: int, open_ch: str, close_ch: str) -> int:
    """Index just past the bracket that closes ``text[start]`` (== open_ch), or -1 if incomplete."""
    depth = 0
    for i in range(start, len(text)):
        c = text[i]
        if c == open_ch:
            depth += 1
        elif c == close_ch:
            depth -= 1
            if depth == 0:
                return i + 1
    return -1


class ReplyParser:
    """Incremental framer for dashboard replies: partial data waits for more bytes;
    several replies in one read come out as several replies; garbage up to the next
    ``;`` comes out as :class:`Unparseable`."""

    MAX_BUFFER = 1 << 20

    def __init__(self) -> None:
        self._buf = ""

    def feed(self, data: bytes) -> list[Reply | Unparseable]:
        self._buf += data.decode("utf-8", errors="replace")
        out: list[Reply | Unparseable] = []
        while self._buf:
            item, consumed = self._parse_one(self._buf)
            if consumed == 0:
                break
            self._buf = self._buf[consumed:]
            if item is not None:
                out.append(item)
        if len(self._buf) > self.MAX_BUFFER:
            out.append(Unparseable(self._buf[:200], "reply buffer overflow without a terminator"))
            self._buf = ""
        return out

    @staticmethod
    def _parse_one(buf: str) -> tuple[Reply | Unparseable | None, int]:
        stripped = buf.lstrip()
        lead = len(buf) - len(stripped)
        if not stripped:
            return None, len(buf)
        m = _REPLY_HEAD.match(buf)
        if m is None:
            # Is it possibly the start of a reply that is still arriving?
            if re.fullmatch(r"\s*-?\d*\s*,?\s*", buf):
                return None, 0
            if "Not Tcp" in buf or "not tcp" in buf.lower():
                end = buf.find(";")
                n = len(buf) if end < 0 else end + 1
                return Unparseable(buf[:n].strip(), "controller is not in TCP/IP control mode"), n
            end = buf.find(";")
            if end < 0:
                return None, 0
            return Unparseable(buf[: end + 1].strip(), "not an ErrorID,{...},Cmd; reply"), end + 1
        brace = m.end() - 1
        vend = _scan_balanced(buf, brace, "{", "}")
        if vend < 0:
            return None, 0
        rest = buf[vend:]
        m2 = re.match(r"\s*,", rest)
        if m2 is None:
            if not rest.strip():
                return None, 0
            end = buf.find(";", vend)
            if end < 0:
                return None, 0
            return Unparseable(buf[lead : end + 1], "missing echo after value field"), end + 1
        echo_start = vend + m2.end()
        paren = buf.find("(", echo_start)
        semi = buf.find(";", echo_start)
        if paren < 0 or (0 <= semi < paren):
            if semi < 0:
                return None, 0
            # echo without parentheses (e.g. an unknown command echoed verbatim)
            return Reply(
                int(m.group(1)), buf[brace + 1 : vend - 1], buf[echo_start:semi].strip(), buf[lead : semi + 1]
            ), semi + 1
        pend = _scan_balanced(buf, paren, "(", ")")
        if pend < 0:
            return None, 0
        semi = buf.find(";", pend)
        if semi < 0:
            return None, 0
        if buf[pend:semi].strip():
            return Unparseable(buf[lead : semi + 1], "unexpected text after echoed command"), semi + 1
        reply = Reply(
            error_id=int(m.group(1)),
            values_text=buf[brace + 1 : vend - 1],
            echo=buf[echo_start:pend].strip(),
            raw=buf[lead : semi + 1],
        )
        return reply, semi + 1


def parse_reply(text: str) -> Reply:
    """Parse exactly one complete reply (tests, simple tools)."""
    items = ReplyParser().feed(text.encode())
    if len(items) != 1 or not isinstance(items[0], Reply):
        raise ProtocolError(f"not exactly one well-formed reply: {text!r}")
    return items[0]


def parse_error_ids(values_text: str) -> list[int]:
    """GetErrorID values in either shape: V4.5 ``[[c...],[s1],...,[s6]]`` or V4.6 ``[id,...]``."""
    text = values_text.strip()
    if not text:
        return []
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ProtocolError(f"GetErrorID value is not a JSON list: {text!r}") from exc

    def flatten(x: object) -> Iterable[int]:
        if isinstance(x, list):
            for y in x:
                yield from flatten(y)
        elif isinstance(x, int | float):
            yield int(x)
        else:
            raise ProtocolError(f"unexpected item {x!r} in GetErrorID value {text!r}")

    return list(flatten(data))


def format_reply(error_id: int, values: Sequence[object] | str, echo: str) -> str:
    if isinstance(values, str):
        body = values
    else:
        body = ",".join(fmt_float(v) if isinstance(v, float) else str(v) for v in values)
    return f"{error_id},{{{body}}},{echo};"


# --------------------------------------------------------------------------- server side
@dataclass
class ParsedCommand:
    """A command as the controller sees it. Values stay text; the handler converts them."""

    name: str  # as written
    args: list[str] = field(default_factory=list)
    kwargs: dict[str, str] = field(default_factory=dict)
    raw: str = ""

    @property
    def key(self) -> str:
        return self.name.strip().lower()


class CommandFramer:
    """Incremental framer for commands arriving on 29999: a command ends at its closing ``)``.
    Text with no parenthesis is cut at a newline or ``;`` so a malformed line still gets a reply."""

    MAX_BUFFER = 1 << 16

    def __init__(self) -> None:
        self._buf = ""

    def feed(self, data: bytes) -> list[str]:
        self._buf += data.decode("utf-8", errors="replace")
        out: list[str] = []
        while True:
            buf = self._buf.lstrip(" \t\r\n;")
            if not buf:
                self._buf = ""
                break
            paren = buf.find("(")
            brk = min((i for i in (buf.find("\n"), buf.find(";")) if i >= 0), default=-1)
            if paren < 0 or (0 <= brk < paren):
                if brk < 0:
                    self._buf = buf
                    if len(buf) > self.MAX_BUFFER:
                        out.append(buf[:200])
                        self._buf = ""
                    break
                out.append(buf[:brk])
                self._buf = buf[brk + 1 :]
                continue
            end = _scan_balanced(buf, paren, "(", ")")
            if end < 0:
                self._buf = buf
                if len(buf) > self.MAX_BUFFER:
                    out.append(buf[:200])
                    self._buf = ""
                break
            out.append(buf[:end])
            self._buf = buf[end:]
        return out


def _split_top(text: str) -> list[str]:
    """Split on commas that are not inside braces/brackets/parentheses."""
    parts, depth, cur = [], 0, []
    for c in text:
        if c in "{[(":
            depth += 1
        elif c in "}])":
            depth -= 1
        if c == "," and depth == 0:
            parts.append("".join(cur))
            cur = []
        else:
            cur.append(c)
    parts.append("".join(cur))
    return [p.strip() for p in parts]


_NAME = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*\(")


def parse_command(text: str) -> ParsedCommand:
    """``Name(a, {1,2}, k = v)`` → ParsedCommand; raises ProtocolError when not of that form."""
    m = _NAME.match(text)
    if m is None or not text.rstrip().endswith(")"):
        raise ProtocolError(f"not a command: {text!r}")
    inner = text[m.end() : text.rstrip().rfind(")")]
    cmd = ParsedCommand(name=m.group(1), raw=text)
    if not inner.strip():
        return cmd
    for part in _split_top(inner):
        if not part:
            raise ProtocolError(f"empty parameter in {text!r}")
        kv = re.match(r"^([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.*)$", part, re.S)
        if kv and not part.startswith("{"):
            cmd.kwargs[kv.group(1).lower()] = kv.group(2).strip()
        else:
            if cmd.kwargs:
                # positional after keyword: counts as a malformed parameter list
                raise ProtocolError(f"positional parameter after keyword in {text!r}")
            cmd.args.append(part)
    return cmd


def parse_point(text: str, n: int = 6) -> list[float]:
    """``{1,2,3,4,5,6}`` → floats; ValueError when not a point of n numbers."""
    t = text.strip()
    if not (t.startswith("{") and t.endswith("}")):
        raise ValueError(f"point must be {{...}}, got {text!r}")
    items = [x.strip() for x in t[1:-1].split(",")]
    if len(items) != n:
        raise ValueError(f"point needs {n} values, got {len(items)}")
    return [float(x) for x in items]


# --------------------------------------------------------------------------- feedback
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
