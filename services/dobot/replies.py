"""Dobot V4 dashboard replies: ``ErrorID,{values},<echo of the command>;`` with no newline.

Incremental: partial data waits for more bytes, garbage comes out as :class:`Unparseable`; queue
commands return their ResultID in ``{}`` (a client must accept ``{}``).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from services.dobot.commands import fmt_float


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


def scan_balanced(text: str, start: int, open_ch: str, close_ch: str) -> int:
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
        vend = scan_balanced(buf, brace, "{", "}")
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
        pend = scan_balanced(buf, paren, "(", ")")
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
