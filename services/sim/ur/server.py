"""The simulated UR controller on the wire: RTDE (30004), the dashboard server (29999) and the
script ports (30001-30003), on a loopback address only, driven by a 500 Hz controller clock.

ur_rtde fixes the RTDE and script ports (``RTDE(hostname, 30004)``, ``ScriptClient(..., 30003)``,
and RTDEControlInterface opens the dashboard on 29999), so two simulated controllers on one machine
differ by address, not port: 127.0.0.0/8 is all loopback on Linux, and tests give each sim its own
127.x.y.z (:func:`loopback_address`). The ports stay configurable for clients that can choose them.

Clock: each tick advances the controller's ``timestamp`` by exactly 2 ms; ticks are paced to wall
time × ``speed``; a machine too busy to keep up slows the clock rather than skipping ticks, so every
data package is one control cycle after the previous one.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import os
import random
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from services.rtde import codec
from services.rtde.codec import Framer, Package, Recipe, RTDEProtocolError
from services.rtde.codes import MessageType
from services.rtde.dashboard import WELCOME, LineFramer, parse_line
from services.rtde.fields import FieldType, input_type, output_type
from services.rtde.script import ScriptFramer
from services.sim.ur import dashboard
from services.sim.ur.controller import (
    CONTROLLER_VERSION,
    POLYSCOPE_VERSION,
    SERIAL_NUMBER,
    TICK_S,
    URController,
)

log = logging.getLogger("pickplace.sim.ur.server")

MAX_FREQUENCY_HZ = 1.0 / TICK_S
WRITE_BUFFER_LIMIT = 4 * 1024 * 1024  # a client this far behind is not reading: drop it
BEHIND_REBASE_S = 0.05  # further behind wall time than this: slow the clock instead of catching up


@dataclass(frozen=True)
class URPorts:
    rtde: int = 30004
    dashboard: int = 29999
    script: tuple[int, ...] = (30001, 30002, 30003)


def check_loopback(host: str) -> str:
    try:
        ok = ipaddress.ip_address(host).is_loopback
    except ValueError:
        ok = host == "localhost"
    if not ok:
        raise ValueError(f"the simulated UR controller listens on loopback only, not {host!r}")
    return host


def loopback_address(n: int) -> str:
    """A distinct loopback address for sim number ``n`` (1 … 16 million): 127.x.y.z, never 127.0.0.1."""
    if not 1 <= n < 2**24 - 2:
        raise ValueError(f"loopback sim number must be within 1..{2**24 - 3}, got {n}")
    n += 1  # skip 127.0.0.1, where a Dobot sim or anything else may hold 29999/30004
    return f"127.{(n >> 16) & 255}.{(n >> 8) & 255}.{n & 255}"


def free_loopback_host(ports: URPorts | None = None, tries: int = 200) -> str:
    """A loopback address 127.x.y.z on which every port of ``ports`` is free now (a random start,
    so parallel test processes rarely collide; a sim that then fails to bind raises at once)."""
    ports = ports or URPorts()
    rng = random.Random(os.getpid() ^ time.time_ns())
    for _ in range(tries):
        host = loopback_address(rng.randrange(1, 2**24 - 3))
        socks: list[socket.socket] = []
        try:
            for port in (ports.rtde, ports.dashboard, *ports.script):
                s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                socks.append(s)
                s.bind((host, port))
            return host
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError(f"no loopback address with ports {ports} free after {tries} tries")


class _RTDESession:
    """One RTDE client: its recipes and whether its output stream runs."""

    def __init__(self, server: URSimServer, writer: asyncio.StreamWriter):
        self.server = server
        self.writer = writer
        self.inputs: dict[int, Recipe] = {}
        self.output: Recipe | None = None
        self.divisor = 1
        self.started = False
        self.owned: set[str] = set()

    def handle(self, pkg: Package) -> bytes | None:
        t = pkg.type
        if t == MessageType.REQUEST_PROTOCOL_VERSION:
            return codec.protocol_version_reply(codec.parse_protocol_request(pkg.payload) in (1, 2))
        if t == MessageType.GET_URCONTROL_VERSION:
            return codec.controller_version_reply(CONTROLLER_VERSION)
        if t == MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS:
            return self._setup_outputs(pkg.payload)
        if t == MessageType.CONTROL_PACKAGE_SETUP_INPUTS:
            return self._setup_inputs(pkg.payload)
        if t == MessageType.CONTROL_PACKAGE_START:
            self.started = self.output is not None
            return codec.start_pause_reply(MessageType.CONTROL_PACKAGE_START, self.started)
        if t == MessageType.CONTROL_PACKAGE_PAUSE:
            self.started = False
            return codec.start_pause_reply(MessageType.CONTROL_PACKAGE_PAUSE, True)
        if t == MessageType.DATA_PACKAGE:
            recipe = self.inputs.get(pkg.payload[0]) if pkg.payload else None
            if recipe is None:
                return codec.text_message(f"data package for unknown input recipe {pkg.payload[:1].hex()}")
            self.server.controller.apply_inputs(recipe.unpack(pkg.payload))
            return None
        return codec.text_message(f"unknown RTDE package type {t}")

    def _setup_outputs(self, payload: bytes) -> bytes:
        frequency, names = codec.parse_setup_outputs(payload)
        types = [output_type(n) for n in names]
        words = [t.value if t else "NOT_FOUND" for t in types]
        if not names or None in types or not 0 < frequency <= MAX_FREQUENCY_HZ:
            return codec.setup_reply(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS, 0, words)
        ok_types: list[FieldType] = [t for t in types if t is not None]
        self.output = Recipe(1, names, tuple(ok_types))
        self.divisor = max(1, round(MAX_FREQUENCY_HZ / frequency))
        return codec.setup_reply(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS, 1, words)

    def _setup_inputs(self, payload: bytes) -> bytes:
        names = codec.split_names(payload)
        owners = self.server.input_owners
        words: list[str] = []
        ok_types: list[FieldType] = []
        for n in names:
            t = input_type(n)
            if t is None:
                words.append("NOT_FOUND")
            elif owners.get(n, self) is not self:
                words.append("IN_USE")
            else:
                words.append(t.value)
                ok_types.append(t)
        if not names or len(ok_types) != len(names):
            log.warning("input recipe %s refused: %s", ",".join(names), ",".join(words))
            return codec.setup_reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS, 0, words)
        rid = len(self.inputs) + 1
        self.inputs[rid] = Recipe(rid, names, tuple(ok_types))
        for n in names:
            owners[n] = self
            self.owned.add(n)
        return codec.setup_reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS, rid, words)

    def release(self) -> None:
        for n in self.owned:
            if self.server.input_owners.get(n) is self:
                del self.server.input_owners[n]


class URSimServer:
    """Async context manager: listening on enter, every connection closed on exit."""

    def __init__(
        self,
        controller: URController,
        host: str = "127.0.0.1",
        ports: URPorts | None = None,
        speed: float = 1.0,
    ):
        self.controller = controller
        self.host = check_loopback(host)
        self.ports = ports or URPorts()
        if not 0 < speed <= 100:
            raise ValueError(f"sim speed must be within (0, 100], got {speed}")
        self.speed = speed
        self.input_owners: dict[str, _RTDESession] = {}
        self._sessions: set[_RTDESession] = set()
        self._writers: set[asyncio.StreamWriter] = set()
        self._servers: list[asyncio.Server] = []
        self._clock: asyncio.Task[None] | None = None
        self._after_tick: list[Callable[[], None]] = []
        self.tick_event = asyncio.Event()

    async def __aenter__(self) -> URSimServer:
        try:
            await self._listen()
        except BaseException:
            await self.close()
            raise
        self._clock = asyncio.create_task(self._run_clock(), name=f"sim-ur-clock-{self.host}")
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def close(self) -> None:
        if self._clock is not None:
            self._clock.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._clock
            self._clock = None
        await self._drop_connections()
        for s in self._servers:
            s.close()
        for s in self._servers:
            await s.wait_closed()
        self._servers.clear()

    async def cut_links(self, outage_s: float = 0.0) -> None:
        """A cable pulled and put back after ``outage_s`` (wall time: how long the fault is injected):
        every client connection closed, and no new one accepted until the cable is back."""
        if outage_s > 0:
            for s in self._servers:
                s.close()
            self._servers.clear()
        await self._drop_connections()
        if outage_s > 0:
            await asyncio.sleep(outage_s)
            await self._listen()

    async def _listen(self) -> None:
        self._servers.append(await asyncio.start_server(self._rtde, self.host, self.ports.rtde))
        self._servers.append(await asyncio.start_server(self._dashboard, self.host, self.ports.dashboard))
        for port in self.ports.script:
            self._servers.append(await asyncio.start_server(self._script, self.host, port))

    async def _drop_connections(self) -> None:
        for w in list(self._writers):
            w.close()
        for w in list(self._writers):
            with contextlib.suppress(Exception):
                await w.wait_closed()
        self._writers.clear()

    # ------------------------------------------------------------------ clock
    async def _run_clock(self) -> None:
        loop = asyncio.get_running_loop()
        period = TICK_S / self.speed
        next_t = loop.time()
        while True:
            self.controller.tick()
            self._publish()
            for fn in list(self._after_tick):
                fn()
            self.tick_event.set()
            self.tick_event.clear()
            next_t += period
            delay = next_t - loop.time()
            if delay < -BEHIND_REBASE_S:
                next_t = loop.time()
            await asyncio.sleep(max(delay, 0.0))

    def _publish(self) -> None:
        due = [s for s in self._sessions if s.started and s.output and self.controller.ticks % s.divisor == 0]
        if not due:
            return
        names: set[str] = set()
        for s in due:
            assert s.output is not None
            names.update(s.output.names)
        values = self.controller.outputs(names)
        for s in due:
            assert s.output is not None
            if s.writer.is_closing():
                continue
            if s.writer.transport.get_write_buffer_size() > WRITE_BUFFER_LIMIT:
                log.warning("RTDE client at %s is not reading: dropped", s.writer.get_extra_info("peername"))
                s.writer.close()
                continue
            s.writer.write(codec.pack(MessageType.DATA_PACKAGE, s.output.pack(values)))

    # ------------------------------------------------------------------ connections
    async def _rtde(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        session = _RTDESession(self, writer)
        self._sessions.add(session)
        self._writers.add(writer)
        framer = Framer()
        try:
            while data := await reader.read(65536):
                for pkg in framer.feed(data):
                    reply = session.handle(pkg)
                    if reply is not None:
                        writer.write(reply)
        except (RTDEProtocolError, ConnectionError) as exc:
            log.warning("RTDE connection dropped: %s", exc)
        finally:
            self._sessions.discard(session)
            session.release()
            await self._close_writer(writer)

    async def _dashboard(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writers.add(writer)
        framer = LineFramer()
        try:
            writer.write((WELCOME + "\n").encode())
            while data := await reader.read(4096):
                for line in framer.feed(data):
                    req = parse_line(line)
                    reply = dashboard.answer(self.controller, req, POLYSCOPE_VERSION, SERIAL_NUMBER)
                    writer.write((reply + "\n").encode())
                    if req.command is not None and req.command.value == "quit":
                        return
        except (ValueError, ConnectionError) as exc:
            log.warning("dashboard connection dropped: %s", exc)
        finally:
            await self._close_writer(writer)

    async def _script(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writers.add(writer)
        framer = ScriptFramer()
        try:
            while data := await reader.read(65536):
                for program in framer.feed(data):
                    self.controller.run_program(program)
        except (ValueError, ConnectionError) as exc:
            log.warning("script connection dropped: %s", exc)
        finally:
            await self._close_writer(writer)

    async def _close_writer(self, writer: asyncio.StreamWriter) -> None:
        self._writers.discard(writer)
        writer.close()
        with contextlib.suppress(Exception):
            await writer.wait_closed()

    # ------------------------------------------------------------------ tests and tools
    def after_tick(self, fn: Callable[[], None]) -> Callable[[], None]:
        """Call ``fn`` after every control cycle (a test's probe); returns the remover."""
        self._after_tick.append(fn)
        return lambda: self._after_tick.remove(fn)

    def snapshot(self) -> dict[str, Any]:
        c = self.controller
        return {
            "timestamp": c.timestamp_s,
            "q": c.q.copy(),
            "robot_mode": c.robot_mode,
            "safety_mode": c.safety_mode,
            "runtime_state": c.runtime_state,
            "digital_outputs": c.digital_outputs,
            # the twin's jaws, when a twin is behind the controller
            "gripper_closed": getattr(c.engine, "gripper_closed", None),
            "gripper_opening_m": getattr(c.engine, "gripper_opening_m", None),
        }
