"""The ServoJ feed watchdog over real sockets: a driver that stalls mid-stream, a gRPC client that dies
mid-motion, a task that never sends the trajectory it said would continue, and the simulated
controller's own watchdog as the sim app configures it.

Judged by the controller's command log (stamped on its clock), its state and the driver's counters —
never by wall-clock gaps."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Any

import numpy as np
import pytest
from pickplace.v1 import robot_pb2, robot_pb2_grpc

from services.common import grpc_util
from services.common.errors import ContinuationLateError, ExecutionError, StartMismatchError
from services.common.settings import Settings
from services.dobot import RobotMode
from services.kinematics.interpolation import quintic_move
from services.kinematics.trajectory import JointLimits, JointTrajectory
from services.robot.client import DobotClient
from services.robot.driver import RobotDriver
from services.robot.service import RobotService, build_driver
from services.sim.app import build_sim_server, servo_watchdog_margin
from services.sim.controller import FaultKind, TrackingFault
from tests.conftest import HOME

pytestmark = pytest.mark.integration

PERIOD = 0.03


def _without_sim_watchdog(settings: Settings) -> Settings:
    """A controller that holds a starved stream's last target (no watchdog of its own): the driver's
    watchdog is the only one."""
    return settings.model_copy(
        update={"sim": settings.sim.model_copy(update={"servo_watchdog_margin_s": None})}
    )


@pytest.fixture
async def holding_sim(settings: Settings) -> AsyncIterator[Any]:
    async with build_sim_server(
        _without_sim_watchdog(settings), "kinematic", ports={"dashboard": 0, "feedback": 0, "slow": 0}
    ) as sim:
        yield sim


def _pointing_at(settings: Settings, sim: Any) -> Settings:
    r = settings.robot.model_copy(
        update={"dashboard_port": sim.ports["dashboard"], "feedback_port": sim.ports["feedback"]}
    )
    return settings.model_copy(update={"robot": r})


@pytest.fixture
async def driver(settings: Settings, holding_sim: Any) -> AsyncIterator[RobotDriver]:
    d = build_driver(_pointing_at(settings, holding_sim))
    await d.start()
    await d.enable()
    yield d
    await d.close()
    await d.client.close()


def _long_move(d: RobotDriver, deg: float = 60.0) -> JointTrajectory:
    goal = HOME + np.deg2rad([deg, 0, 0, 0, 0, 0])
    lim = JointLimits.from_spec(d.spec, velocity_scale=0.3, acceleration_scale=0.3)
    return quintic_move(d.joint_positions(), goal, joint_names=d.spec.joint_names, limits=lim)


def _halves(traj: JointTrajectory) -> tuple[JointTrajectory, JointTrajectory]:
    """``traj`` cut at its middle knot: the first half ends in motion, the second continues it."""
    half = round(traj.duration / 2 / PERIOD) * PERIOD
    ts = np.arange(0.0, half + 1e-9, PERIOD)
    rest_ts = np.arange(half, traj.duration + 1e-9, PERIOD)
    return (
        JointTrajectory(traj.joint_names, ts, *traj.sample(ts)),
        JointTrajectory(traj.joint_names, rest_ts - half, *traj.sample(rest_ts)),
    )


def _servo_log(sim: Any) -> list[tuple[int, str]]:
    with sim.lock:
        return list(sim.controller.command_log)


class StallingLink:
    """The real link, except that the ``stall_at``-th ServoJ never returns: a driver-side stall
    (an event loop starved of the stream task, a reply that never comes)."""

    def __init__(self, link: DobotClient, stall_at: int):
        self._link = link
        self._stall_at = stall_at
        self.servo_calls = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._link, name)

    async def servo_j(self, q: Any, t_s: float) -> int | None:
        self.servo_calls += 1
        if self.servo_calls == self._stall_at:
            await asyncio.Event().wait()  # stalled for good
        return await self._link.servo_j(q, t_s)

    async def servo_j_many(self, qs: Any, t_s: float) -> list[int | None]:
        """The driver's pipelined batch, one target after another (so the stall falls inside it)."""
        return [await self.servo_j(q, t_s) for q in qs]


async def test_a_driver_stalled_mid_stream_stops_the_arm_once_the_controller_runs_dry(driver, holding_sim):
    real = driver.client
    driver.client = StallingLink(real, stall_at=12)  # type: ignore[assignment]
    traj = _long_move(driver)
    with pytest.raises(ExecutionError, match="ServoJ watchdog: the stream was not fed"):
        await driver.execute_trajectory(traj, PERIOD)
    assert driver.watchdog_trips == 1 and driver.monitor_trips == 0
    log = _servo_log(holding_sim)
    servo = [(ms, text) for ms, text in log if text.startswith("ServoJ")]
    stops = [ms for ms, text in log if text == "Stop()"]
    assert len(servo) == 11  # the 12th never went out
    assert stops and stops[-1] >= servo[-1][0]
    assert not [text for ms, text in log if ms > stops[-1] and text.startswith("ServoJ")]
    # it tripped on the controller's clock no sooner than the period plus the margin after the last
    # target could have started (it arrived before it started)
    bound_ms = (PERIOD + driver.settings.robot.servo_watchdog_margin_s) * 1000
    assert driver.last_fault_stamp_ms is not None
    assert driver.last_fault_stamp_ms - servo[-1][0] >= bound_ms
    fb = await real.wait_feedback(lambda f: f.robot_mode == RobotMode.ENABLE, 2.0)
    assert np.rad2deg(fb.q[0] - HOME[0]) < 59.0  # stopped, far short of the goal
    # the driver is not wedged: the next motion runs from where the arm stopped
    driver.client = real
    res = await driver.move_joints(HOME, speed_ratio=100)
    assert np.allclose(res.final_q, HOME, atol=1e-6)
    print(
        f"driver stall: watchdog tripped {driver.last_fault_stamp_ms - servo[-1][0]} ms (controller clock) "
        f"after the last ServoJ arrived; Stop reached the controller {stops[-1] - servo[-1][0]} ms after it"
    )


async def test_a_continuation_that_never_comes_stops_the_arm_and_the_next_is_judged_from_rest(
    driver, holding_sim
):
    first, second = _halves(_long_move(driver, 40.0))
    await driver.execute_trajectory(first, PERIOD, continues=True)
    n_servo = sum(1 for _, t in _servo_log(holding_sim) if t.startswith("ServoJ"))
    # the task "dies": nothing follows. The driver's watch of the gap stops the arm by itself.
    await driver.client.wait_controller(lambda f: driver.watchdog_trips >= 1, 10.0)
    await driver.client.wait_feedback(lambda f: f.robot_mode == RobotMode.ENABLE, 2.0)
    log = _servo_log(holding_sim)
    assert log[-1][1] == "Stop()"
    assert sum(1 for _, t in log if t.startswith("ServoJ")) == n_servo
    assert "ServoJ watchdog" in str(driver.last_fault)
    # the late successor would start the stopped arm at full speed: judged from rest, it is refused,
    # as a late continuation the task plans again from rest
    with pytest.raises(ContinuationLateError, match=r"accelerate.*plan it again from rest"):
        await driver.execute_trajectory(second, PERIOD)


async def test_a_continuation_off_an_arm_still_settling_after_its_motion_ran_out_is_late_not_a_mismatch(
    settings, holding_sim
):
    """Seed 1074 under load: the motion a trajectory continued had run out before it came, and the arm,
    tracking on behind its last target, stood 1.59° off its start: refused as a start mismatch, which the
    cycle cannot mend while it takes the arm to be moving, so it gave up. It is a late continuation (plan it
    again from rest); a trajectory planned from rest that starts off the arm is still a mismatch."""
    # a gap watch that cannot trip meanwhile: the motion runs out and nothing stops it
    s = _pointing_at(settings, holding_sim)
    s = s.model_copy(update={"robot": s.robot.model_copy(update={"servo_watchdog_margin_s": 10.0})})
    d = build_driver(s)
    await d.start()
    try:
        await d.enable()
        first, second = _halves(_long_move(d, 20.0))
        # the arm settles 1.5° behind its reference (the lag of a real drive at speed, held still here)
        with holding_sim.lock:
            holding_sim.controller.tracking_fault = TrackingFault(
                FaultKind.OFFSET, 0, offset_rad=np.deg2rad(-1.5)
            )
        await d.execute_trajectory(first, PERIOD, continues=True)
        # the motion runs out: the controller has executed its last target and idles, the arm behind it
        await d.client.wait_feedback(
            lambda f: (
                f.robot_mode == RobotMode.ENABLE and abs(f.q[0] - first.positions[-1][0]) > np.deg2rad(1.2)
            ),
            5.0,
        )
        assert d.watchdog_trips == 0
        n_servo = sum(1 for _, t in _servo_log(holding_sim) if t.startswith("ServoJ"))
        with pytest.raises(ContinuationLateError, match=r"run out.*plan it again from rest"):
            await d.execute_trajectory(second, PERIOD)
        # nothing was sent, and the arm is at rest where the first motion left it
        assert sum(1 for _, t in _servo_log(holding_sim) if t.startswith("ServoJ")) == n_servo
        assert float(np.max(np.abs(d.feedback.qd))) < 0.01
        # planned from rest (it does not start moving), the same offset is a start mismatch
        at_rest = JointTrajectory(second.joint_names, second.times, second.positions, 0 * second.velocities,
                                  0 * second.accelerations)  # fmt: skip
        with pytest.raises(StartMismatchError, match="measured joints"):
            await d.execute_trajectory(at_rest, PERIOD)
    finally:
        with holding_sim.lock:
            holding_sim.controller.tracking_fault = None
        await d.close()
        await d.client.close()


async def test_a_grpc_client_that_dies_mid_motion_leaves_the_arm_stopped(settings, holding_sim):
    s = _pointing_at(settings, holding_sim)
    async with RobotService(s, grpc_port=0) as svc:
        d = svc.driver
        await d.enable()
        traj = _long_move(d, 80.0)  # seconds of motion
        ch = grpc_util.channel("127.0.0.1", svc.grpc_port)
        stub = robot_pb2_grpc.RobotControllerStub(ch)
        call = stub.ExecuteTrajectory(
            robot_pb2.ExecuteTrajectoryRequest(trajectory=traj.to_proto(), servo_period_s=PERIOD)
        )
        await d.client.wait_feedback(
            lambda f: f.robot_mode == RobotMode.RUNNING and f.q[0] - HOME[0] > np.deg2rad(5), 10.0
        )
        with holding_sim.lock:
            died_ms = holding_sim.controller.clock_ms
        await ch.close(grace=None)  # the client dies: its call is cut
        with pytest.raises(asyncio.CancelledError):
            await call
        fb = await d.client.wait_feedback(lambda f: f.robot_mode == RobotMode.ENABLE, 5.0)
        log = _servo_log(holding_sim)
        stops = [ms for ms, text in log if text == "Stop()" and ms >= died_ms]
        assert stops, "no Stop reached the controller after the client died"
        assert not [t for ms, t in log if ms > stops[0] and t.startswith("ServoJ")]
        assert np.rad2deg(fb.q[0] - HOME[0]) < 79.0
        later = await d.client.wait_controller_time(0.3)
        assert np.array_equal(later.q, fb.q)
        print(f"client died: Stop at the controller {stops[0] - died_ms} ms (controller clock) later")


def test_the_sim_apps_watchdog_margin_follows_the_settings_and_the_speed(settings):
    assert settings.sim.servo_watchdog_margin_s == 0.5
    sim = build_sim_server(settings, "kinematic", ports={"dashboard": 0, "feedback": 0, "slow": 0})
    assert sim.controller.config.servo_watchdog_margin_s == 0.5
    assert servo_watchdog_margin(0.5, 3.0) == 1.5  # host latency is wall time: 3× longer on its clock
    assert servo_watchdog_margin(0.5, 0.5) == 0.5
    assert servo_watchdog_margin(0.5, 1e9) is None  # as fast as it can: no host keeps up
    assert servo_watchdog_margin(None, 1.0) is None
    off = build_sim_server(_without_sim_watchdog(settings), "kinematic")
    assert off.controller.config.servo_watchdog_margin_s is None


async def test_the_sim_apps_controller_halts_a_stream_whose_host_died(sim_server):
    """As configured by the sim app (margin 0.5 s): a host that dies with 1 s of targets queued is
    halted t + 0.5 s after its last ServoJ, short of the targets it queued."""
    ctl = sim_server.controller
    host = DobotClient("127.0.0.1", sim_server.ports["dashboard"], sim_server.ports["feedback"])
    async with DobotClient(
        "127.0.0.1", sim_server.ports["dashboard"], sim_server.ports["feedback"]
    ) as watcher:
        await host.connect()
        await host.enable()
        targets = [HOME + np.deg2rad([1.0 * k, 0, 0, 0, 0, 0]) for k in range(1, 11)]
        ids = await asyncio.gather(*(host.servo_j(q, 0.1) for q in targets))
        await host.close()  # dies with 10 targets (1 s of motion) queued
        assert None not in ids
        first_id = min(i for i in ids if i is not None)
        # halted: enabled and idle again once the stream has begun (a feedback packet composed
        # before the targets were queued says ENABLE too)
        fb = await watcher.wait_feedback(
            lambda f: f.robot_mode == RobotMode.ENABLE and f.current_command_id >= first_id, 5.0
        )
        assert ctl.servo_watchdog_trips == 1
        assert ids[-1] is not None and fb.current_command_id < ids[-1]
        last_servo_ms = max(ms for ms, text in ctl.command_log if text.startswith("ServoJ"))
        assert ctl.servo_watchdog_tripped_ms is not None
        assert (
            ctl.servo_watchdog_tripped_ms - last_servo_ms <= (0.1 + 0.5) * 1000 + 8
        )  # t + margin (+ a tick)
        assert np.rad2deg(fb.q[0] - HOME[0]) < 10.0 - 1.0
