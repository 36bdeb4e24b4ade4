"""The simulated Dobot's sockets: dashboard (29999), feedback (30004, 8 ms) and
slow feedback (30005, 200 ms) on loopback, around a :class:`SimController`.

A clock thread ticks the controller in sim time (``speed`` × real time, or as
fast as possible with ``speed=0``) and hands every feedback packet to the event
loop, which writes it whole to each connected client. Every tick advances sim time
by one period and every packet is stamped with that sim time (the controller's
clock), so the feedback and the simulated world never disagree. When the machine
cannot keep ``speed`` the clock slows (no tick is dropped, none skipped ahead): the
:class:`ClockPacer` makes up a short lag, beyond it re-anchors, and the server logs
and exports the speed it achieved.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from services.common.metrics import CellMetrics
from services.common.shell import ServiceShell
from services.dobot import CommandFramer
from services.sim.controller import SimController

log = logging.getLogger("pickplace.sim.server")

MAX_BACKLOG_BYTES = 1440 * 256  # drop packets for a client that stops reading
CATCH_UP_S = 0.05  # wall lag made up by ticking back-to-back; beyond it the sim clock slows instead
SPEED_WINDOW_S = 2.0  # wall seconds over which the achieved speed is measured
SLOW_WARNING_EVERY_S = 30.0
SLOW_RATIO = 0.95  # achieved below this share of the asked speed: say so


@dataclass
class ClockPacer:
    """When each tick is due on the wall clock (pure: the caller reads the clock). A tick that comes
    late is still one period of sim time; a lag beyond ``max_lag_s`` is given up (the sim clock slowed),
    never made up by jumping sim time."""

    period_s: float  # sim seconds per tick
    speed: float  # sim time per wall time; 0 = as fast as possible
    next_wall_s: float
    max_lag_s: float = CATCH_UP_S
    late_ticks: int = 0
    given_up_s: float = 0.0  # wall seconds of lag the clock gave up (it ran slower than ``speed``)

    def after_tick(self, now_s: float) -> float:
        """A tick just ran at ``now_s``: the wall delay before the next one (0 = at once)."""
        if self.speed <= 0:
            return 0.0
        self.next_wall_s += self.period_s / self.speed
        delay = self.next_wall_s - now_s
        if delay < 0:
            self.late_ticks += 1
            if -delay > self.max_lag_s:
                self.given_up_s += -delay
                self.next_wall_s = now_s
            return 0.0
        return delay


@dataclass
class SpeedWindow:
    """The sim speed achieved over windows of ``window_s`` wall seconds (pure)."""

    window_s: float
    wall0_s: float
    sim0_s: float
    achieved: float | None = None

    def update(self, wall_s: float, sim_s: float) -> float | None:
        """The achieved speed when a window closed at this call, else None."""
        if wall_s - self.wall0_s < self.window_s:
            return None
        self.achieved = (sim_s - self.sim0_s) / (wall_s - self.wall0_s)
        self.wall0_s, self.sim0_s = wall_s, sim_s
        return self.achieved


class SimDobotServer(ServiceShell):
    """The simulated controller's sockets and clock, as a shell: ``async with build_sim_server(s) as sim``."""

    kind = "sim-dobot"

    def __init__(
        self,
        controller: SimController,
        host: str = "127.0.0.1",
        dashboard_port: int = 29999,
        feedback_port: int = 30004,
        slow_feedback_port: int | None = 30005,
        period_s: float = 0.008,
        slow_period_s: float = 0.2,
        speed: float = 1.0,
        metrics: CellMetrics | None = None,
    ):
        super().__init__()
        self.controller = controller
        self.host = host
        self._ports = {"dashboard": dashboard_port, "feedback": feedback_port, "slow": slow_feedback_port}
        self.period_s = period_s
        self.slow_every = max(1, round(slow_period_s / period_s))
        self.speed = speed
        self.lock = threading.RLock()  # guards the controller (clock thread vs. dashboard)
        self._servers: dict[str, asyncio.base_events.Server] = {}
        self._fast: set[asyncio.StreamWriter] = set()
        self._slow: set[asyncio.StreamWriter] = set()
        self._dash: set[asyncio.StreamWriter] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.ticks = 0
        self.late_ticks = 0
        self.achieved_speed: float | None = None  # over the last SPEED_WINDOW_S of wall time
        self.metrics = metrics
        self.ports: dict[str, int] = {}

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        self._loop = asyncio.get_running_loop()
        stack.callback(self.controller.engine.close)
        stack.push_async_callback(self._close_listeners)
        self._servers["dashboard"] = await asyncio.start_server(
            self._serve_dashboard, self.host, self._ports["dashboard"]
        )
        self._servers["feedback"] = await asyncio.start_server(
            self._make_feed_handler(self._fast), self.host, self._ports["feedback"]
        )
        if self._ports["slow"] is not None:
            self._servers["slow"] = await asyncio.start_server(
                self._make_feed_handler(self._slow), self.host, self._ports["slow"]
            )
        self.ports = {k: s.sockets[0].getsockname()[1] for k, s in self._servers.items()}
        self._stop.clear()
        self._thread = threading.Thread(target=self._clock, name="sim-dobot-clock", daemon=True)
        self._thread.start()
        stack.push_async_callback(self._stop_clock)
        log.info("simulated Dobot listening on %s: %s", self.host, self.ports)

    async def stop(self) -> None:
        """Switch the controller off now (clock stopped, listeners closed, clients dropped); leaving
        the ``async with`` afterwards does nothing more."""
        await self.__aexit__(None, None, None)

    def links(self) -> dict[str, bool]:
        clock = self._thread is not None and self._thread.is_alive()
        return {"clock": clock, **{name: srv.is_serving() for name, srv in self._servers.items()}}

    async def _stop_clock(self) -> None:
        self._stop.set()
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 2.0)
            self._thread = None

    async def _close_listeners(self) -> None:
        await self.cut_link()
        self._servers.clear()
        self._loop = None

    async def cut_link(self) -> None:
        """Fault injection: the network to the controller is gone (listeners closed, clients dropped)
        while the controller and its clock run on — the arm keeps executing what it was given."""
        for srv in self._servers.values():
            srv.close()
        self.drop_clients()
        for srv in self._servers.values():
            with contextlib.suppress(Exception):
                await asyncio.wait_for(srv.wait_closed(), 2.0)

    async def restore_link(self) -> None:
        """Fault injection: listen again on the same ports after :meth:`cut_link`."""
        handlers: dict[str, Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]] = {
            "dashboard": self._serve_dashboard,
            "feedback": self._make_feed_handler(self._fast),
            "slow": self._make_feed_handler(self._slow),
        }
        for name, port in self.ports.items():
            if not self._servers[name].is_serving():
                self._servers[name] = await asyncio.start_server(handlers[name], self.host, port)

    def drop_clients(self) -> None:
        """Close every client connection (as if the cable were pulled); listeners stay up."""
        for group in (self._fast, self._slow, self._dash):
            for w in list(group):
                with contextlib.suppress(Exception):
                    w.transport.abort()
            group.clear()

    # ------------------------------------------------------------------ clock thread
    def _clock(self) -> None:
        period = self.period_s
        pacer = ClockPacer(period, self.speed, time.perf_counter())
        window = SpeedWindow(SPEED_WINDOW_S, pacer.next_wall_s, self.controller.sim_time)
        warned_at = -SLOW_WARNING_EVERY_S
        while not self._stop.is_set():
            with self.lock:
                try:
                    self.controller.tick(period)
                except Exception:
                    log.exception("controller tick failed")
                packet = self.controller.feedback_bytes()
                sim_now = self.controller.sim_time
            self.ticks += 1
            slow = self.ticks % self.slow_every == 0
            loop = self._loop
            if loop is not None:
                with contextlib.suppress(RuntimeError):
                    loop.call_soon_threadsafe(self._broadcast, packet, slow)
            now = time.perf_counter()
            late_before = pacer.late_ticks
            delay = pacer.after_tick(now)
            if pacer.late_ticks > late_before:
                self.late_ticks = pacer.late_ticks
                if self.metrics is not None:
                    self.metrics.sim_late_ticks.inc()
            achieved = window.update(now, sim_now)
            if achieved is not None:
                self.achieved_speed = achieved
                if self.metrics is not None:
                    self.metrics.sim_clock_speed.set(achieved)
                if (
                    self.speed > 0
                    and achieved < SLOW_RATIO * self.speed
                    and now - warned_at > SLOW_WARNING_EVERY_S
                ):
                    warned_at = now
                    log.warning(
                        "the machine cannot keep --speed %.2g: the sim clock slowed to %.2f× over the last "
                        "%.0f s (%d late ticks so far); feedback stays stamped in sim time",
                        self.speed,
                        achieved,
                        SPEED_WINDOW_S,
                        pacer.late_ticks,
                    )
            if delay > 0:
                self._stop.wait(delay)
            elif self.speed <= 0:
                time.sleep(0)

    def _broadcast(self, packet: bytes, slow: bool) -> None:
        groups = [self._fast, self._slow] if slow else [self._fast]
        for group in groups:
            for w in list(group):
                if w.is_closing():
                    group.discard(w)
                    continue
                if w.transport.get_write_buffer_size() > MAX_BACKLOG_BYTES:
                    continue
                w.write(packet)

    # ------------------------------------------------------------------ sockets
    def _make_feed_handler(
        self, group: set[asyncio.StreamWriter]
    ) -> Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]:
        async def handler(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            group.add(writer)
            try:
                while await reader.read(1024):  # clients send nothing; wait for EOF
                    pass
            except (ConnectionError, asyncio.CancelledError):
                pass
            finally:
                group.discard(writer)
                with contextlib.suppress(Exception):
                    writer.close()

        return handler

    async def _serve_dashboard(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        framer = CommandFramer()
        self._dash.add(writer)
        peer = writer.get_extra_info("peername")
        log.debug("dashboard client %s connected", peer)
        try:
            while True:
                data = await reader.read(4096)
                if not data:
                    break
                texts = framer.feed(data)
                if texts:
                    # the commands of one packet in one go, as a controller parses what one read brings:
                    # taken one by one, a tick slipped in between them (32 ms of controller clock between
                    # the 3rd and 4th of eight pipelined ServoJ on a loaded machine)
                    with self.lock:
                        replies = [self.controller.handle(text) for text in texts]
                    writer.write("".join(replies).encode())
                await writer.drain()
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            self._dash.discard(writer)
            with contextlib.suppress(Exception):
                writer.close()
            log.debug("dashboard client %s disconnected", peer)
