"""The robot link under faults, over real loopback sockets: bad feedback from a fake controller, late
and stray dashboard replies, and outages of the simulated controller's network.

Judged by the client's counters and link events and by the controller's own clock and command log,
never by wall-clock gaps (the outage lengths are only how long the fault is injected)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable

import numpy as np
import pytest

from services import dobot
from services.common.errors import RobotCommunicationError
from services.common.settings import ReconnectSettings
from services.dobot import RobotMode
from services.robot.client import DobotClient
from services.robot.feedback import FeedbackState, LinkEventKind, LinkState

pytestmark = pytest.mark.integration

FAST_RECONNECT = ReconnectSettings(max_attempts=3, base_delay_s=0.02, max_delay_s=0.1)


# ---------------------------------------------------------------------- a fake controller
def _packet(stamp_ms: int, **fields: object) -> bytes:
    rec = dobot.new_feedback()
    rec["RobotMode"] = int(RobotMode.ENABLE)
    rec["TimeStamp"] = stamp_ms
    rec["QActual"] = [0, 0, 90, 0, -90, 0]
    rec["QTarget"] = [0, 0, 90, 0, -90, 0]
    rec["SafetyState"] = 0xFF
    for k, v in fields.items():
        rec[k] = v
    return dobot.encode_feedback(rec)


class FakeController:
    """A dashboard that answers from a script and a feedback port that plays one script per
    connection (the last one repeats for later connections)."""

    def __init__(self, feeds: list[Callable[[asyncio.StreamWriter], object]]):
        self.feeds = feeds
        self.feed_connections = 0
        self.commands: list[str] = []
        self.answer: Callable[[str, list[str]], list[str]] = lambda cmd, seen: [f"0,{{}},{cmd};"]
        self._servers: list[asyncio.base_events.Server] = []
        self._writers: set[asyncio.StreamWriter] = set()
        self.ports: dict[str, int] = {}

    async def __aenter__(self) -> FakeController:
        dash = await asyncio.start_server(self._dashboard, "127.0.0.1", 0)
        feed = await asyncio.start_server(self._feedback, "127.0.0.1", 0)
        self._servers = [dash, feed]
        self.ports = {
            "dashboard": dash.sockets[0].getsockname()[1],
            "feedback": feed.sockets[0].getsockname()[1],
        }
        return self

    async def __aexit__(self, *exc: object) -> None:
        for s in self._servers:
            s.close()
        for w in self._writers:
            w.transport.abort()
        for s in self._servers:
            await s.wait_closed()

    async def _dashboard(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        framer = dobot.CommandFramer()
        self._writers.add(writer)
        with contextlib.suppress(ConnectionError, asyncio.CancelledError):
            while data := await reader.read(4096):
                for cmd in framer.feed(data):
                    self.commands.append(cmd)
                    for reply in self.answer(cmd, self.commands):
                        writer.write(reply.encode())
                await writer.drain()

    async def _feedback(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        script = self.feeds[min(self.feed_connections, len(self.feeds) - 1)]
        self.feed_connections += 1
        self._writers.add(writer)
        with contextlib.suppress(ConnectionError, asyncio.CancelledError):
            await script(writer)  # type: ignore[misc]
            await reader.read()  # hold the connection open until the client goes


def client_for(fake: FakeController, **kw: object) -> DobotClient:
    return DobotClient(
        "127.0.0.1",
        fake.ports["dashboard"],
        fake.ports["feedback"],
        request_timeout_s=1.0,
        reconnect=FAST_RECONNECT,
        **kw,  # type: ignore[arg-type]
    )


async def steady(writer: asyncio.StreamWriter, start_ms: int = 50_000) -> None:
    """Good packets every 8 ms of (fake) controller time, forever."""
    stamp = start_ms
    while True:
        writer.write(_packet(stamp))
        await writer.drain()
        stamp += 8
        await asyncio.sleep(0.008)


async def until(c: DobotClient, done: Callable[[], bool], limit_s: float = 60.0) -> None:
    """Wait, packet by packet, until ``done()`` (errors of a link that is down are part of the wait)."""
    async with asyncio.timeout(limit_s):
        while not done():
            with contextlib.suppress(RobotCommunicationError):
                await c.next_feedback(0.5)


# ---------------------------------------------------------------------- bad feedback
async def test_nan_truncated_and_garbage_feedback_is_dropped_counted_and_never_handed_on():
    good_stamps = [1000, 1008, 1016, 1024, 1032, 1040, 1048]
    bad_run_go = asyncio.Event()

    async def first(writer: asyncio.StreamWriter) -> None:
        nan_q = [np.nan, 0, 90, 0, -90, 0]
        chunks = [
            _packet(1000),
            _packet(1004, QActual=nan_q),  # NaN joint
            _packet(1008),
            _packet(1010, QDActual=[0, np.inf, 0, 0, 0, 0]),  # infinite speed
            _packet(1016),
            _packet(1018)[:700],  # truncated: the framer drops it
            _packet(1024),
            b"\x00garbage\xa0\x05 not a packet" * 10,  # garbage between packets
            _packet(1032),
            _packet(900),  # the clock ran backwards
            _packet(1036, ToolVectorActual=[np.nan] * 6),
            _packet(1037, QActual=[0, 0, 1e6, 0, 0, 0]),  # implausible joint
            _packet(1040),
            _packet(1044, RobotMode=200),
            _packet(1048),
        ]
        for chunk in chunks:
            writer.write(chunk)
        await writer.drain()
        await bad_run_go.wait()
        for k in range(30):  # a run of bad packets: a link fault
            writer.write(_packet(2000 + 8 * k, QActual=[np.nan] * 6))
        await writer.drain()

    async with FakeController([first, steady]) as fake:
        c = client_for(fake, bad_feedback_run=25)
        seen: list[FeedbackState] = []
        c.add_listener(seen.append)
        try:
            await c.connect()
            await until(c, lambda: c.packets_received >= len(good_stamps))
            assert [fb.timestamp_ms for fb in seen] == good_stamps
            assert c.feedback_rejected == 6
            assert c.feedback_rejections["controller clock ran backwards"] == 1
            assert c.framer_resyncs >= 2
            assert c.link is LinkState.UP and c.link_faults == 0

            waiter = asyncio.create_task(c.wait_controller(lambda fb: False, 3600.0))
            await asyncio.sleep(0)
            bad_run_go.set()
            with pytest.raises(RobotCommunicationError, match="25 bad packets in a row"):
                await waiter
            assert c.link_faults == 1 and c.feedback_rejected == 6 + 25
            # the client reconnects by itself; the second connection is sound
            await until(c, lambda: c.link is LinkState.UP and fake.feed_connections >= 2)
            fb = await c.next_feedback()
            assert fb.timestamp_ms >= 50_000
            kinds = [e.kind for e in c.link_events]
            assert kinds == [LinkEventKind.RESTORED, LinkEventKind.LOST, LinkEventKind.RESTORED]
            # no state with a non-finite value ever left the client
            for s in seen:
                for v in (s.q, s.qd, s.q_target, s.T_base_tool, s.tcp_force):
                    assert np.all(np.isfinite(v))
        finally:
            await c.close()


# ---------------------------------------------------------------------- replies
async def test_late_reply_to_a_timed_out_command_is_discarded_never_given_to_the_next():
    """The controller answers a MovJ only when the next command arrives: the late reply (ID 101)
    belongs to the timed-out request and is dropped; the next MovJ — the very same text — gets 102."""
    held: list[str] = []
    ids = iter(range(101, 200))

    def answer(cmd: str, seen: list[str]) -> list[str]:
        if cmd.startswith("MovJ") and not held and len(seen) == 1:
            held.append(f"0,{{{next(ids)}}},{cmd};")
            return []
        out, held[:] = list(held), []
        rid = next(ids) if cmd.startswith("MovJ") else None
        return [*out, f"0,{{{'' if rid is None else rid}}},{cmd};"]

    async with FakeController([steady]) as fake:
        fake.answer = answer
        c = client_for(fake)
        try:
            await c.connect()
            cmd = dobot.mov_j_joint([10, 0, 90, 0, -90, 0])
            with pytest.raises(RobotCommunicationError, match="no reply"):
                await c.raw_request(cmd, timeout_s=0.2)
            reply = await c.raw_request(cmd)
            assert reply.result_id == 102
            assert c.late_replies_discarded == 1
            # and the stream stays in step afterwards
            assert (await c.raw_request(dobot.mov_j_joint([20, 0, 90, 0, -90, 0]))).result_id == 103
        finally:
            await c.close()


async def test_stray_and_out_of_order_replies_are_never_misdelivered():
    def answer(cmd: str, seen: list[str]) -> list[str]:
        if cmd == "RobotMode()":
            # a stray reply first (echo of nothing we sent), then ours with a reformatted echo
            return ["0,{7},MovJ(joint={1,2,3,4,5,6});", "0,{5},robotmode();"]
        if cmd.startswith("GetAngle"):
            return []  # never answered: the next reply shows it was skipped
        return [f"0,{{1}},{cmd};"]

    async with FakeController([steady]) as fake:
        fake.answer = answer
        c = client_for(fake)
        try:
            await c.connect()
            assert await c.robot_mode() == 5
            assert c.unmatched_replies == 1
            skipped = asyncio.create_task(c.raw_request("GetAngle()", timeout_s=30.0))
            await asyncio.sleep(0)
            reply = await c.raw_request("PositiveKin(0,0,90,0,-90,0)")
            assert reply.echo == "PositiveKin(0,0,90,0,-90,0)"
            with pytest.raises(RobotCommunicationError, match="resynchronised"):
                await skipped
        finally:
            await c.close()


# ---------------------------------------------------------------------- outages
@pytest.fixture
async def moving_client(sim_server) -> AsyncIterator[DobotClient]:  # type: ignore[no-untyped-def]
    c = DobotClient(
        "127.0.0.1",
        sim_server.ports["dashboard"],
        sim_server.ports["feedback"],
        request_timeout_s=1.0,
        reconnect=FAST_RECONNECT,
    )
    async with c:
        yield c


@pytest.mark.parametrize("outage_s", [0.5, 3.0, 10.0])
async def test_link_comes_back_after_an_outage_and_stops_the_cut_motion(sim_server, moving_client, outage_s):
    c, ctl = moving_client, sim_server.controller
    await c.enable()
    target = np.deg2rad([150, 0, 90, 0, -90, 0])
    rid = await c.mov_j(target, v=5)  # ~9°/s: still moving after the longest outage
    await c.wait_feedback(lambda fb: fb.robot_mode == RobotMode.RUNNING, 2.0)
    waiter = asyncio.create_task(c.wait_motion_done(rid, 120.0))
    await asyncio.sleep(0)

    await sim_server.cut_link()
    with pytest.raises(RobotCommunicationError, match="link lost"):
        await waiter  # failed at the loss, not at its deadline
    assert c.link is LinkState.RECONNECTING and c.stop_owed
    with pytest.raises(RobotCommunicationError, match="refused"):
        await c.mov_j(target)  # no motion before the owed Stop
    await asyncio.sleep(outage_s)  # the fault itself lasts this long (wall clock)
    with sim_server.lock:
        restored_at_ms = ctl.clock_ms
        n_before = len(ctl.command_log)
    assert ctl.mode == RobotMode.RUNNING  # the arm kept moving while cut off
    await sim_server.restore_link()

    await until(c, lambda: c.link is LinkState.UP and not c.stop_owed)
    with pytest.raises(RobotCommunicationError, match="cut by a robot link loss"):
        await c.wait_motion_done(rid, 10.0)  # never resumed, never resent
    events = list(c.link_events)
    lost = next(e for e in events if e.kind is LinkEventKind.LOST)
    up = next(e for e in events if e.kind is LinkEventKind.RESTORED and e.epoch >= lost.epoch)
    stop = next(e for e in events if e.kind is LinkEventKind.STOP_SENT)
    assert up.stamp_ms is not None and lost.stamp_ms is not None and stop.stamp_ms is not None
    recovery_ms = up.stamp_ms - restored_at_ms
    # the first command the controller heard after the outage is the Stop
    after = [text for _, text in list(ctl.command_log)[n_before:]]
    assert after[0] == "Stop()"
    stop_at_ms = next(ms for ms, text in list(ctl.command_log)[n_before:] if text == "Stop()")
    # the arm is at rest short of the target and stays there
    fb = await c.wait_feedback(lambda f: f.robot_mode == RobotMode.ENABLE, 2.0)
    assert np.rad2deg(fb.q[0]) < 149.0
    later = await c.wait_controller_time(0.3)
    assert np.allclose(later.q, fb.q, atol=1e-9) and later.current_command_id == fb.current_command_id
    print(
        f"outage {outage_s:.1f}s: feedback back {recovery_ms} ms, Stop at the controller "
        f"{stop_at_ms - restored_at_ms} ms after the network returned (controller clock); "
        f"link lost at stamp {lost.stamp_ms}, {c.feedback_connect_failures} failed feedback connects"
    )
    # usable again
    rid2 = await c.mov_j(np.deg2rad([0, 0, 90, 0, -90, 0]), v=100)
    done = await c.wait_motion_done(rid2, 60.0)
    assert done.current_command_id == rid2


async def test_a_host_that_stops_feeding_servoj_is_halted_by_the_controller_watchdog():
    from services.kinematics.robot_models import NOVA5
    from services.sim.controller import ControllerConfig, SimController
    from services.sim.dobot_server import SimDobotServer
    from services.sim.engine import KinematicEngine
    from tests.conftest import HOME

    ctl = SimController(NOVA5, KinematicEngine(), ControllerConfig(servo_watchdog_margin_s=0.016), q0=HOME)
    sim = SimDobotServer(ctl, "127.0.0.1", 0, 0, None)
    async with sim:
        host = DobotClient(
            "127.0.0.1", sim.ports["dashboard"], sim.ports["feedback"], reconnect=FAST_RECONNECT
        )
        watcher = DobotClient(
            "127.0.0.1", sim.ports["dashboard"], sim.ports["feedback"], reconnect=FAST_RECONNECT
        )
        async with watcher:
            await host.connect()
            await host.enable()
            # pipelined, as a look-ahead goes out: the 8 commands reach the controller in one write
            targets = [HOME + np.deg2rad([0.5 * k, 0, 0, 0, 0, 0]) for k in range(1, 9)]
            ids = await host.servo_j_many(targets, 0.05)
            await host.close()  # the host dies with 8 targets (0.4 s) queued
            assert None not in ids
            first_id = min(i for i in ids if i is not None)
            # halted: enabled and idle again once the stream has begun (a feedback packet composed
            # before the targets were queued says ENABLE too)
            fb = await watcher.wait_feedback(
                lambda f: f.robot_mode == RobotMode.ENABLE and f.current_command_id >= first_id, 5.0
            )
            assert ctl.servo_watchdog_trips >= 1
            assert ids[-1] is not None and fb.current_command_id < ids[-1]
            assert np.rad2deg(fb.q[0] - HOME[0]) < 4.0 - 0.5  # halted short of the last target
            later = await watcher.wait_controller_time(0.3)
            assert np.array_equal(later.q, fb.q)
