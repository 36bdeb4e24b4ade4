"""Parameters of dashboard commands as the V4 controller checks them, and the ErrorIDs it answers.

Pure: text in, numbers out, :class:`CommandError` carrying the ErrorID (``-3000X`` wrong type /
``-4000X`` out of range of required parameter X, ``-5000X`` / ``-6000X`` of optional ones).
"""

from __future__ import annotations

import numpy as np

from services import dobot

PARAM_LIMIT_DEG = 360.0  # a joint value beyond ±360° is a parameter range error (-4000X)


class CommandError(Exception):
    """A command is refused with a protocol ErrorID."""

    def __init__(self, error_id: int):
        super().__init__(error_id)
        self.error_id = error_id


def nargs(cmd: dobot.ParsedCommand, lo: int, hi: int | None = None) -> None:
    hi = lo if hi is None else hi
    if not lo <= len(cmd.args) <= hi:
        raise CommandError(dobot.ErrorID.PARAM_COUNT)


def param_float(text: str, pos: int, optional: bool = False) -> float:
    try:
        v = float(text)
    except ValueError:
        raise CommandError((-50000 if optional else -30000) - pos) from None
    if not np.isfinite(v):
        raise CommandError((-60000 if optional else -40000) - pos)
    return v


def param_int(text: str, pos: int, lo: int, hi: int, optional: bool = False) -> int:
    v = param_float(text, pos, optional)
    if v != int(v):
        raise CommandError((-50000 if optional else -30000) - pos)
    if not lo <= v <= hi:
        raise CommandError((-60000 if optional else -40000) - pos)
    return int(v)


def opt_ratio(cmd: dobot.ParsedCommand, key: str, default: int, lo: int = 1) -> int:
    if key not in cmd.kwargs:
        return default
    return param_int(cmd.kwargs[key], 1, lo, 100, optional=True)


def param_point(text: str, pos: int) -> np.ndarray:
    try:
        pts = dobot.parse_point(text, 6)
    except ValueError:
        raise CommandError(-30000 - pos) from None
    arr = np.array(pts)
    if not np.all(np.isfinite(arr)):
        raise CommandError(-40000 - pos)
    return arr


def joint_or_pose(cmd: dobot.ParsedCommand) -> tuple[str, np.ndarray]:
    """MovJ/MovL target: ``joint={..}`` or ``pose={..}`` (or six positional pose values)."""
    if "joint" in cmd.kwargs:
        if cmd.args:
            raise CommandError(dobot.ErrorID.PARAM_COUNT)
        q_deg = param_point(cmd.kwargs["joint"], 1)
        if np.any(np.abs(q_deg) > PARAM_LIMIT_DEG):
            raise CommandError(-40001)
        return "joint", q_deg
    if "pose" in cmd.kwargs:
        if cmd.args:
            raise CommandError(dobot.ErrorID.PARAM_COUNT)
        return "pose", param_point(cmd.kwargs["pose"], 1)
    if len(cmd.args) == 6:
        return "pose", np.array([param_float(a, i + 1) for i, a in enumerate(cmd.args)])
    raise CommandError(dobot.ErrorID.PARAM_COUNT)
