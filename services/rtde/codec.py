"""RTDE packages, sans-I/O: the 3-byte header, a stream framer, recipes and the control messages.

Wire facts (UR RTDE guide, "Protocol"): every package is ``uint16 size`` (header included), ``uint8
type``, then the payload; all numbers big-endian. Protocol version 2: a data package's payload starts
with its ``uint8`` recipe id. Used by the simulated controller (server side) and by tests (client side).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from services.rtde.codes import MessageType
from services.rtde.fields import FieldType

HEADER = struct.Struct(">HB")
HEADER_SIZE = HEADER.size
PROTOCOL_VERSION = 2
MAX_PACKAGE = 65535


class RTDEProtocolError(ValueError):
    """Bytes that are not an RTDE package, or a payload that does not fit its recipe."""


@dataclass(frozen=True)
class Package:
    type: int  # a MessageType value (unknown types are kept, not rejected: the caller answers them)
    payload: bytes


def pack(msg_type: int, payload: bytes = b"") -> bytes:
    size = HEADER_SIZE + len(payload)
    if size > MAX_PACKAGE:
        raise RTDEProtocolError(f"RTDE package of {size} bytes exceeds {MAX_PACKAGE}")
    return HEADER.pack(size, msg_type) + payload


class Framer:
    """Feed stream bytes, get whole packages; a partial package waits for more bytes."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> Iterator[Package]:
        self._buf += data
        while len(self._buf) >= HEADER_SIZE:
            size, msg_type = HEADER.unpack_from(self._buf)
            if size < HEADER_SIZE:
                raise RTDEProtocolError(f"RTDE header announces {size} bytes, less than its own 3")
            if len(self._buf) < size:
                return
            payload = bytes(self._buf[HEADER_SIZE:size])
            del self._buf[:size]
            yield Package(msg_type, payload)


@dataclass(frozen=True)
class Recipe:
    """One set-up recipe: its id, variable names and their types, in order."""

    id: int
    names: tuple[str, ...]
    types: tuple[FieldType, ...]

    @property
    def struct(self) -> struct.Struct:
        return struct.Struct(">" + "".join(t.struct_format for t in self.types))

    def pack(self, values: Mapping[str, Any]) -> bytes:
        """A data package payload (recipe id first) from a value per name (vectors as sequences)."""
        flat: list[Any] = []
        for name, t in zip(self.names, self.types, strict=True):
            v = values[name]
            if t.count == 1:
                flat.append(v)
            else:
                seq = list(v)
                if len(seq) != t.count:
                    raise RTDEProtocolError(f"{name} needs {t.count} values, got {len(seq)}")
                flat.extend(seq)
        return bytes([self.id]) + self.struct.pack(*flat)

    def unpack(self, payload: bytes) -> dict[str, Any]:
        """The values of a data package payload (recipe id first)."""
        if not payload or payload[0] != self.id:
            raise RTDEProtocolError(
                f"data package for recipe {payload[:1].hex()} decoded as recipe {self.id}"
            )
        s = self.struct
        if len(payload) - 1 != s.size:
            raise RTDEProtocolError(
                f"recipe {self.id} data is {len(payload) - 1} bytes, its {len(self.names)} fields need {s.size}"
            )
        flat = s.unpack_from(payload, 1)
        out: dict[str, Any] = {}
        i = 0
        for name, t in zip(self.names, self.types, strict=True):
            out[name] = flat[i] if t.count == 1 else tuple(flat[i : i + t.count])
            i += t.count
        return out


def split_names(text: bytes) -> tuple[str, ...]:
    """The comma-separated variable names of a setup request (ur_rtde leaves a trailing comma)."""
    return tuple(n.strip() for n in text.decode("ascii", "replace").split(",") if n.strip())


# ---------------------------------------------------------------- client → controller
def request_protocol_version(version: int = PROTOCOL_VERSION) -> bytes:
    return pack(MessageType.REQUEST_PROTOCOL_VERSION, struct.pack(">H", version))


def setup_outputs_request(names: Iterable[str], frequency_hz: float) -> bytes:
    return pack(
        MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS,
        struct.pack(">d", frequency_hz) + ",".join(names).encode("ascii"),
    )


def setup_inputs_request(names: Iterable[str]) -> bytes:
    return pack(MessageType.CONTROL_PACKAGE_SETUP_INPUTS, ",".join(names).encode("ascii"))


def parse_protocol_request(payload: bytes) -> int:
    if len(payload) != 2:
        raise RTDEProtocolError(f"protocol version request needs 2 bytes, got {len(payload)}")
    return int(struct.unpack(">H", payload)[0])


def parse_setup_outputs(payload: bytes) -> tuple[float, tuple[str, ...]]:
    """(frequency, names) of a version-2 output setup."""
    if len(payload) < 8:
        raise RTDEProtocolError("output setup needs an 8-byte frequency before the names")
    return float(struct.unpack_from(">d", payload)[0]), split_names(payload[8:])


# ---------------------------------------------------------------- controller → client
def protocol_version_reply(accepted: bool) -> bytes:
    return pack(MessageType.REQUEST_PROTOCOL_VERSION, bytes([int(accepted)]))


def controller_version_reply(version: Sequence[int]) -> bytes:
    major, minor, bugfix, build = version
    return pack(MessageType.GET_URCONTROL_VERSION, struct.pack(">IIII", major, minor, bugfix, build))


def setup_reply(msg_type: MessageType, recipe_id: int, type_names: Sequence[str]) -> bytes:
    """The answer to an input or output setup: the recipe id (0 = refused) and a type per name."""
    return pack(msg_type, bytes([recipe_id]) + ",".join(type_names).encode("ascii"))


def start_pause_reply(msg_type: MessageType, accepted: bool) -> bytes:
    return pack(msg_type, bytes([int(accepted)]))


def text_message(text: str, source: str = "pickplace-sim", level: int = 3) -> bytes:
    """A version-2 text message: length-prefixed message and source, then a warning level."""
    m, s = text.encode()[:255], source.encode()[:255]
    return pack(MessageType.TEXT_MESSAGE, bytes([len(m)]) + m + bytes([len(s)]) + s + bytes([level]))


def parse_controller_version(payload: bytes) -> tuple[int, int, int, int]:
    major, minor, bugfix, build = struct.unpack(">IIII", payload[:16])
    return int(major), int(minor), int(bugfix), int(build)


def parse_setup_reply(payload: bytes) -> tuple[int, tuple[str, ...]]:
    return payload[0], split_names(payload[1:])
