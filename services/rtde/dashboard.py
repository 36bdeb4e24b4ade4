"""The UR dashboard server's line protocol (port 29999), sans-I/O: commands and the words of replies.

Every command is one line ending in ``\\n``; every reply is one line. The texts are those of UR's
"Dashboard Server e-Series" manual and the checks ur_rtde makes on them (``src/dashboard_client.cpp``:
``play`` must answer exactly "Starting program", ``stop`` "Stopped", ``unlock protective stop``
"Protective stop releasing"). docs/ur/rtde.md lists them with their sources.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass


class DashboardCommand(enum.Enum):
    ROBOTMODE = "robotmode"
    POWER_ON = "power on"
    POWER_OFF = "power off"
    BRAKE_RELEASE = "brake release"
    UNLOCK_PROTECTIVE_STOP = "unlock protective stop"
    CLOSE_SAFETY_POPUP = "close safety popup"
    RESTART_SAFETY = "restart safety"
    PLAY = "play"
    STOP = "stop"
    PAUSE = "pause"
    RUNNING = "running"
    PROGRAM_STATE = "programstate"
    SAFETYSTATUS = "safetystatus"
    SAFETYMODE = "safetymode"
    IS_IN_REMOTE_CONTROL = "is in remote control"
    POLYSCOPE_VERSION = "polyscopeversion"
    GET_SERIAL_NUMBER = "get serial number"
    GET_ROBOT_MODEL = "get robot model"
    GET_LOADED_PROGRAM = "get loaded program"
    IS_PROGRAM_SAVED = "isprogramsaved"
    CLOSE_POPUP = "close popup"
    POPUP = "popup"
    ADD_TO_LOG = "addtolog"
    LOAD = "load"
    QUIT = "quit"
    SHUTDOWN = "shutdown"


WELCOME = "Connected: Universal Robots Dashboard Server"
# commands that take an argument after their name (the rest of the line)
_WITH_ARGUMENT = (DashboardCommand.POPUP, DashboardCommand.ADD_TO_LOG, DashboardCommand.LOAD)


@dataclass(frozen=True)
class DashboardRequest:
    command: DashboardCommand | None  # None: not a command the server knows
    argument: str
    line: str  # as received, without the line end


def parse_line(line: str) -> DashboardRequest:
    """One request line → its command (case-insensitive, as the server reads it)."""
    text = line.strip()
    low = text.lower()
    for cmd in _WITH_ARGUMENT:
        if low == cmd.value or low.startswith(cmd.value + " "):
            return DashboardRequest(cmd, text[len(cmd.value) :].strip(), text)
    try:
        return DashboardRequest(DashboardCommand(low), "", text)
    except ValueError:
        return DashboardRequest(None, "", text)


def not_understood(line: str) -> str:
    return f"could not understand: '{line}'"


class LineFramer:
    """Feed bytes, get whole lines (``\\r\\n`` or ``\\n``); a partial line waits for more bytes."""

    def __init__(self, limit: int = 4096) -> None:
        self._buf = bytearray()
        self._limit = limit

    def feed(self, data: bytes) -> Iterator[str]:
        self._buf += data
        while (i := self._buf.find(b"\n")) >= 0:
            line = bytes(self._buf[:i]).rstrip(b"\r").decode("utf-8", "replace")
            del self._buf[: i + 1]
            yield line
        if len(self._buf) > self._limit:
            self._buf.clear()
            raise ValueError(f"dashboard line longer than {self._limit} bytes")
