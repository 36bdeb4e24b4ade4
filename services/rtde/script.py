"""URScript programs as the controller's script port (30001-30003) receives them, sans-I/O.

A program is ``def name():`` … ``end`` at column 0 (ur_rtde sends ``def rtde_control():\\n`` + its
script + ``end\\n``, ``src/script_client.cpp``); a line outside a program is a single script
command. ur_rtde injects its register offset into the script's header
(``global reg_offset_int = # int register offset\\n`` followed by ``0`` or ``24``).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass

_DEF = re.compile(r"^def\s+(\w+)\s*\(\s*\)\s*:\s*$")
_SEC = re.compile(r"^sec\s+(\w+)\s*\(\s*\)\s*:\s*$")
_INT_OFFSET = re.compile(r"#\s*int register offset\s*\n\s*(\d+)")
_FLOAT_OFFSET = re.compile(r"#\s*float register offset\s*\n\s*(\d+)")
RTDE_CONTROL_MARKER = "RTDE Control Script"  # the textmsg ur_rtde's script prints when it starts


@dataclass(frozen=True)
class Program:
    name: str
    text: str
    secondary: bool  # a ``sec`` program (runs beside the primary one, no motion)

    @property
    def is_rtde_control(self) -> bool:
        """ur_rtde's control script (its register command protocol)."""
        return self.name == "rtde_control" or RTDE_CONTROL_MARKER in self.text

    @property
    def register_offsets(self) -> tuple[int, int]:
        """(int, float) register offsets injected by ur_rtde (0, or 24 for the upper range)."""
        i, f = _INT_OFFSET.search(self.text), _FLOAT_OFFSET.search(self.text)
        return (int(i.group(1)) if i else 0, int(f.group(1)) if f else 0)


class ScriptFramer:
    """Feed bytes from a script port; get each complete program (or single-line command) as it ends."""

    def __init__(self, limit: int = 4 * 1024 * 1024) -> None:
        self._buf = bytearray()
        self._lines: list[str] = []
        self._name: str | None = None
        self._secondary = False
        self._limit = limit

    def feed(self, data: bytes) -> Iterator[Program]:
        self._buf += data
        if len(self._buf) + sum(map(len, self._lines)) > self._limit:
            self._buf.clear()
            self._lines.clear()
            self._name = None
            raise ValueError(f"script longer than {self._limit} bytes")
        while (i := self._buf.find(b"\n")) >= 0:
            line = bytes(self._buf[:i]).rstrip(b"\r").decode("utf-8", "replace")
            del self._buf[: i + 1]
            program = self._line(line)
            if program is not None:
                yield program

    def _line(self, line: str) -> Program | None:
        if self._name is None:
            m = _DEF.match(line) or _SEC.match(line)
            if m is not None:
                self._name, self._secondary, self._lines = m.group(1), line.startswith("sec"), [line]
                return None
            if line.strip():
                return Program("", line, secondary=True)  # a lone script command
            return None
        self._lines.append(line)
        if line.rstrip() == "end":  # the program's own end sits at column 0
            program = Program(self._name, "\n".join(self._lines) + "\n", self._secondary)
            self._name, self._lines = None, []
            return program
        return None
