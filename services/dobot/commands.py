"""Dobot V4 command encoding: ``Name(p1,p2,...)`` with no terminator, floats written like the SDK
(``{:f}``, six decimals), ratios as integers; and which commands queue or pass in alarm state."""

from __future__ import annotations

from collections.abc import Sequence

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
