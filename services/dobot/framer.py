"""The controller side of the dashboard port (for the simulator): command framing and parsing."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from services.dobot.replies import ProtocolError, scan_balanced


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
            end = scan_balanced(buf, paren, "(", ")")
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
    parts: list[str] = []
    cur: list[str] = []
    depth = 0
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
