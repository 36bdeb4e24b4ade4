"""DobotClient ↔ simulated Dobot over real loopback sockets."""

import asyncio
import contextlib
import itertools
import statistics

import numpy as np
import pytest

from services.common.errors import ControllerError, EmergencyStopError, RobotCommunicationError
from services.common.settings import ReconnectSettings
from services.dobot import RobotMode
from services.robot.client import DobotClient
from services.robot.feedback import ClientState, LinkEventKind, LinkState
from tests.conftest import HOME

pytestmark = pytest.mark.integration

FAST_RECONNECT = ReconnectSettings(max_attempts=3, base_delay_s=0.02, max_delay_s=0.1)


def make_client(server, **kw) -> DobotClient:  # type: ignore[no-untyped-def]
    return DobotClient(
        "127.0.0.1",
        server.ports["dashboard"],
        server.ports["feedback"],
        request_timeout_s=1.0,
        reconnect=FAST_RECONNECT,
        **kw,
    )


async def test_enable_movj_completion(sim_server):
    async with make_client(sim_server) as c:
        assert await c.robot_mode() == RobotMode.DISABLED
        await c.enable()
        target = np.deg2rad([10, 20, 30, 40, 50, 60])
        rid = await c.mov_j(target, v=100)
        assert rid is not None and rid >= 1
        fb = await c.wait_motion_done(rid, 10.0)
        assert fb.current_command_id == rid and fb.robot_mode == RobotMode.ENABLE
        assert np.allclose(fb.q, target, atol=1e-6)
        assert np.allclose(await c.get_angles(), target, atol=1e-6)


async def test_joint_limit_alarm_clear_recover(sim_server):
    async with make_client(sim_server) as c:
        await c.enable()
        rid = await c.mov_j(np.deg2rad([0, 0, 170, 0, 0, 0]))
        with pytest.raises(ControllerError) as err:
            await c.wait_motion_done(rid, 5.0)
        assert 68 in err.value.alarms and "joint 3 positive limit" in str(err.value)
        await c.clear_error()
        await c.wait_feedback(lambda fb: fb.robot_mode == RobotMode.ENABLE, 1.0)
        rid = await c.mov_j(np.deg2rad([0, 0, 100, 0, -90, 0]), v=100)
        fb = await c.wait_motion_done(rid, 10.0)
        assert np.isclose(np.rad2deg(fb.q[2]), 100.0, atol=1e-6)


async def test_estop_during_motion(sim_server):
    async with make_client(sim_server) as c:
        await c.enable()
        rid = await c.mov_j(np.deg2rad([120, 0, 90, 0, -90, 0]), v=20)
        await c.wait_feedback(lambda fb: fb.robot_mode == RobotMode.RUNNING, 2.0)
        await c.emergency_stop(True)
        with pytest.raises(EmergencyStopError):
            await c.wait_motion_done(rid, 5.0)
        q1 = (await c.next_feedback()).q
        await asyncio.sleep(0.2)
        q2 = (await c.next_feedback()).q
        assert np.allclose(q1, q2)  # stopped and staying stopped
        assert q2[0] < np.deg2rad(119)
        with pytest.raises(EmergencyStopError):
            await c.enable()
        await c.emergency_stop(False)
        await c.clear_error()
        await c.enable()
        assert await c.robot_mode() == RobotMode.ENABLE


async def test_socket_closed_mid_move_stops_the_arm_and_fails_the_motion(sim_server):
    async with make_client(sim_server) as c:
        await c.enable()
        rid = await c.mov_j(np.deg2rad([60, 0, 90, 0, -90, 0]), v=30)
        await c.wait_feedback(lambda fb: fb.robot_mode == RobotMode.RUNNING, 2.0)
        sim_server.drop_clients()  # cable pulled: both sockets die, the listeners stay
        # the cut motion fails (it is never resent); the client owes the controller a Stop and sends it
        # once the link is back, before any motion command is let through
        with pytest.raises(RobotCommunicationError):
            await c.wait_motion_done(rid, 10.0)
        while c.stop_owed:
            with contextlib.suppress(RobotCommunicationError):
                await c.next_feedback()
        kinds = [e.kind for e in c.link_events]
        assert LinkEventKind.STOP_SENT in kinds[kinds.index(LinkEventKind.LOST) :]
        assert await c.robot_mode() == RobotMode.ENABLE
        q = (await c.next_feedback()).q
        assert np.rad2deg(q[0]) < 59.0  # stopped short of the target
        later = await c.wait_controller_time(0.2)
        assert np.allclose(later.q, q, atol=1e-9)
        # the link is usable again
        rid2 = await c.mov_j(np.deg2rad([0, 0, 90, 0, -90, 0]), v=100)
        fb = await c.wait_motion_done(rid2, 10.0)
        assert fb.current_command_id == rid2 and c.link is LinkState.UP


async def test_pending_request_fails_when_connection_drops():
    """A controller that reads but never answers, then hangs up: the request fails with
    'connection lost' at once, not after its (long) timeout."""
    hang_up = asyncio.Event()

    async def silent(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await reader.read(100)
        await hang_up.wait()
        writer.close()

    server = await asyncio.start_server(silent, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    c = DobotClient("127.0.0.1", port, port, request_timeout_s=30.0, reconnect=FAST_RECONNECT)
    try:
        await c._ensure_dashboard()
        task = asyncio.create_task(c.raw_request("RobotMode()"))
        await asyncio.sleep(0)
        hang_up.set()
        with pytest.raises(RobotCommunicationError, match="connection lost"):
            await asyncio.wait_for(task, 10.0)
    finally:
        await c.close()
        server.close()


async def test_server_gone_gives_bounded_clear_error(sim_server):
    c = make_client(sim_server)
    await c.connect()
    await c.enable()
    await sim_server.stop()  # controller gone for good
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    with pytest.raises(RobotCommunicationError, match="after 3 attempts"):
        await c.robot_mode()
    assert c.state is ClientState.DISCONNECTED
    with pytest.raises(RobotCommunicationError):
        await c.next_feedback(0.3)
    assert loop.time() - t0 < 10  # bounded, nothing hangs
    await c.close()


async def test_unreachable_port_fails_fast():
    c = DobotClient(
        "127.0.0.1", 1, 2, reconnect=ReconnectSettings(max_attempts=2, base_delay_s=0.01, max_delay_s=0.02)
    )
    with pytest.raises(RobotCommunicationError, match=r"127\.0\.0\.1:1 after 2 attempts"):
        await c.connect()
    await c.close()


async def test_malformed_commands_over_socket(sim_server):
    async with make_client(sim_server) as c:
        r = await c.raw_request("NoSuchCommand()")
        assert r.error_id == -10000
        r = await c.raw_request("MovJ(joint={1,2})")
        assert r.error_id == -30001
        r = await c.raw_request("SpeedFactor(1,2,3)")
        assert r.error_id == -20000
        assert await c.robot_mode() == RobotMode.DISABLED  # still serving


async def test_concurrent_requests_matched_by_echo(sim_server):
    async with make_client(sim_server) as c:
        replies = await asyncio.gather(*(c.raw_request(f"PositiveKin({i},0,90,0,-90,0)") for i in range(20)))
        for i, r in enumerate(replies):
            assert r.echo == f"PositiveKin({i},0,90,0,-90,0)"


async def _controller_periods_ms(c: DobotClient, n: int) -> list[int]:
    """The steps of the controller clock (TimeStamp, ms) between the next ``n`` packets seen."""
    stamps = [(await c.next_feedback()).timestamp_ms for _ in range(n + 1)]
    return [b - a for a, b in itertools.pairwise(stamps)]


async def test_feedback_rate_and_slow_port(sim_server):
    # Judged by the controller's clock stamped in each packet, not by when the test happens to read
    # them: packets come every 8 ms on the real-time port, every 200 ms on the slow one (the median
    # step, so that one late tick on a loaded machine does not decide it).
    async with make_client(sim_server) as c:
        n0 = c.packets_received
        steps = await _controller_periods_ms(c, 40)
        assert 7 <= statistics.median(steps) <= 9, str(steps)
        assert c.packets_received - n0 >= 40
    slow = DobotClient(
        "127.0.0.1", sim_server.ports["dashboard"], sim_server.ports["slow"], feedback_timeout_s=5.0
    )
    async with slow:
        steps = await _controller_periods_ms(slow, 4)
        assert 190 <= statistics.median(steps) <= 210, str(steps)
    assert np.allclose(slow.feedback.q, HOME, atol=1e-9)


async def test_wait_deadlines_are_controller_time():
    # A controller whose clock runs at a quarter of the wall (a busy machine): a 0.2 s wait lasts 0.2 s
    # of its clock, judged by the stamps the waiting saw, and ends as TimeoutError (the link is fine).
    from services.kinematics.robot_models import NOVA5
    from services.sim.controller import SimController
    from services.sim.dobot_server import SimDobotServer
    from services.sim.engine import KinematicEngine

    sim = SimDobotServer(
        SimController(NOVA5, KinematicEngine(), q0=HOME), "127.0.0.1", 0, 0, None, speed=0.25
    )
    async with sim, make_client(sim) as c:
        stamps: list[int] = []
        start = (await c.next_feedback()).timestamp_ms
        with pytest.raises(TimeoutError, match="controller time"):
            await c.wait_controller(
                lambda fb: stamps.append(fb.timestamp_ms) is not None, 0.2, since_ms=start
            )
        assert stamps[-1] - start >= 200
        assert stamps[-1] - start <= 200 + 8 * 3  # ended at the first packets past the deadline
        fb = await c.wait_controller_time(0.1)
        assert fb.timestamp_ms - stamps[-1] >= 100


async def test_wait_on_a_stopped_controller_clock_is_a_link_error(sim_server):
    async with make_client(sim_server) as c:
        # the clock thread blocks on the controller's lock: packets stop, the clock with them
        with sim_server.lock, pytest.raises(RobotCommunicationError):
            await c.wait_controller(lambda fb: False, 0.5, wall_guard_s=0.3)


async def test_pipelined_servoj_reach_the_controller_together_and_replies_keep_their_order(sim_server):
    async with make_client(sim_server) as c:
        await c.enable()
        q0 = await c.get_angles()
        targets = [q0 + np.deg2rad([0.2 * k, 0, 0, 0, 0, 0]) for k in range(1, 9)]
        with sim_server.lock:
            n_log = len(sim_server.controller.command_log)
        ids = await c.servo_j_many(targets, 0.03)
        assert all(i is not None for i in ids) and ids == list(range(ids[0], ids[0] + 8))
        with sim_server.lock:
            arrived = [
                ms
                for ms, text in list(sim_server.controller.command_log)[n_log:]
                if text.startswith("ServoJ")
            ]
        # one write: the controller parsed all eight within less than one target's t of its own clock,
        # so none can have found it run dry
        assert len(arrived) == 8 and arrived[-1] - arrived[0] < 30
        fb = await c.wait_motion_done(ids[-1], 10.0)
        assert np.allclose(fb.q, targets[-1], atol=1e-6)
        # the first refused (a disabled controller refuses motion) fails the call as request() would
        await c.disable()
        with pytest.raises(ControllerError, match="ServoJ"):
            await c.servo_j_many(targets[:2], 0.03)
        assert await c.robot_mode() == RobotMode.DISABLED  # the stream stays usable afterwards
