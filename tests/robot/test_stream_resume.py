"""A ServoJ stream whose controller ran dry (the host fell behind) is never continued with a step from
rest: the driver lets the arm rest at its last target and re-times the rest of the stream from rest.

The pure parts (the re-timing, the schedule of what the controller holds) with fixtures; the whole over
real sockets with a host that stalls until the controller has run dry, every command on the wire
checked independently through the bench's recording proxy."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.bench_robot import RecordingProxy, limit_violations
from services.common.errors import LimitViolationError
from services.common.settings import WorkspaceBounds, load_settings
from services.dobot import RobotMode
from services.kinematics.interpolation import quintic_move
from services.kinematics.robot_models import NOVA5
from services.kinematics.trajectory import JointLimits
from services.robot.driver import MAX_WINDOW, RobotDriver, stream_window
from services.robot.feedback import FeedbackState
from services.robot.monitor import StreamMonitor
from services.robot.resume import retime_from_rest, warp
from services.robot.safety import SafetyLimits
from services.robot.service import build_driver
from tests.conftest import HOME

PERIOD = 0.03
LIMITS = SafetyLimits(NOVA5, WorkspaceBounds())


def _plan_at_speed() -> np.ndarray:
    """ServoJ targets of a move at the arm's limits (a quintic over 60° of joint 1)."""
    lim = JointLimits.from_spec(NOVA5, 1.0, 1.0)
    traj = quintic_move(
        HOME, HOME + np.deg2rad([60, 0, 0, 0, 0, 0]), joint_names=NOVA5.joint_names, limits=lim
    )
    n = int(np.ceil(traj.duration / PERIOD))
    return np.atleast_2d(
        traj.sample(np.minimum(np.arange(1, n + 1) * PERIOD, traj.duration), derivatives=0)[0]
    )


def test_the_warp_rises_from_rest_and_then_falls_on_the_plans_targets():
    u = warp(16, 4, 12.0)
    assert 0 < u[0] < 0.05  # the first step from rest is tiny
    assert np.all(np.diff(u) > 0) and np.all(np.diff(u) <= 1.0 + 1e-12)  # never faster than the plan
    assert np.allclose(u[7:11], [4, 5, 6, 7])  # from 2 × 4 periods on: the plan's own targets
    assert u[-1] == 12.0


def test_the_rest_of_a_stream_at_speed_resumes_within_the_limits_and_ends_on_the_plan():
    targets = _plan_at_speed()
    k = len(targets) // 2  # mid-way, at full speed
    with pytest.raises(LimitViolationError):  # as it was: a step from rest
        LIMITS.check_accelerations(targets[k : k + 1], PERIOD, np.vstack([targets[k - 1]] * 2))
    res = retime_from_rest(targets[k - 1], targets[k:], PERIOD, LIMITS)
    LIMITS.check_accelerations(res.targets, PERIOD, np.vstack([targets[k - 1]] * 2))
    LIMITS.check_velocities(res.targets, PERIOD, q_start=targets[k - 1])
    assert np.array_equal(res.targets[-1], targets[-1])
    assert res.reaches_plan and np.allclose(res.targets[-2:], targets[-2:])
    assert len(res.targets) > len(targets) - k  # slower than the plan while it ramps


def test_a_stream_too_short_to_reach_its_plan_says_so():
    targets = _plan_at_speed()
    k = len(targets) // 2  # two targets left of a stream that goes on at speed (a continuing one)
    res = retime_from_rest(targets[k - 1], targets[k : k + 2], PERIOD, LIMITS)
    assert not res.reaches_plan and np.array_equal(res.targets[-1], targets[k + 1])


def test_a_short_stream_at_its_limits_that_ends_in_motion_is_resumed_to_rest_at_its_end():
    """Seed 1000 of the eval under load: the 18 targets of the line out of the release (it flows on into
    the way home, its joints at their acceleration limit) ran dry at their first. No ramp short enough
    to reach the plan's rate stays within the limits, and a longer one reached the last target at speed
    (753°/s² as it stopped there): the rest goes from rest to rest along the same path instead, and what
    was to continue it is planned again from there (``reaches_plan`` False)."""
    case = np.load(Path(__file__).parent / "data" / "short_stream_ending_in_motion.npz")
    rest, remaining, period = case["q_rest"], case["remaining"], float(case["period"])
    limits = SafetyLimits(NOVA5, load_settings("sim", overrides={"logging": {"file": None}}).robot.workspace)
    res = retime_from_rest(rest, remaining, period, limits)
    assert not res.reaches_plan
    LIMITS.check_velocities(res.targets, period, q_start=rest)
    limits.check_accelerations(res.targets, period, np.vstack([rest, rest]))
    limits.check_accelerations(res.targets[-1:], period, res.targets[-2:])  # and then holds it, at rest
    assert np.array_equal(res.targets[-1], remaining[-1])
    # along the plan's own path: every target on the polyline through the plan's targets
    path = np.vstack([rest, remaining])
    for q in res.targets:
        seg = np.clip(
            ((q - path[:-1]) * (path[1:] - path[:-1])).sum(1) / ((path[1:] - path[:-1]) ** 2).sum(1), 0, 1
        )
        assert np.min(np.max(np.abs(path[:-1] + seg[:, None] * (path[1:] - path[:-1]) - q), axis=1)) < 1e-9


def test_the_window_holds_the_learned_margin_in_host_time_at_any_simulator_speed():
    # a 130 ms stall of the host at 2x: 260 ms of the controller's clock, a margin of 520 ms
    margin_ms = 2.0 * 130.0 * 2.0
    window = stream_window(4, 2.0, margin_ms, PERIOD)
    assert window * PERIOD * 1000 >= margin_ms  # 16 targets (480 ms) could never keep it
    assert window <= 2 * MAX_WINDOW
    # a real cell (1x) holds no more than it did, however slow the host
    assert stream_window(4, 1.0, 5000.0, PERIOD) == MAX_WINDOW
    assert stream_window(4, 1.0, 0.0, PERIOD) == 4  # a quiet host: the configured look-ahead


def _fb(stamp_ms: int, current_id: int, mode: RobotMode = RobotMode.RUNNING) -> FeedbackState:
    z = np.zeros(6)
    return FeedbackState(
        q=HOME.copy(), qd=z, q_target=HOME.copy(), T_base_tool=np.eye(4), tcp_force=z, robot_mode=int(mode),
        current_command_id=current_id, digital_inputs=0, digital_outputs=0, enabled=True, error=False,
        collision=False, running=mode == RobotMode.RUNNING, estop=False, timestamp_ms=stamp_ms, received_ns=0,
    )  # fmt: skip


def test_the_schedule_of_what_the_controller_holds_is_a_lower_bound_on_running_dry():
    m = StreamMonitor(HOME, PERIOD, 0.05, 0.25)
    for rid in (11, 12, 13, 14):  # sent together on the packet stamped 1000
        m.sent(HOME, rid, stamp_ms=1000)
    m.on_feedback(_fb(1008, 10))  # not started yet: the first cannot start before 1008
    assert m.dry_at_ms(_fb(1008, 10)) == pytest.approx(1008 + 4 * 30)
    fb = _fb(1080, 13)  # executing the third: one left unstarted, but the schedule says more
    m.on_feedback(fb)
    assert m.unstarted(13) == 1
    assert m.dry_at_ms(fb) == pytest.approx(1128)
    m.from_rest()  # a new segment: only what is held counts until its first target is sent
    assert m.dry_at_ms(_fb(1300, 14, RobotMode.ENABLE)) == pytest.approx(1300)


# ---------------------------------------------------------------------- over real sockets
@pytest.fixture
async def proxied(robot_settings: Any, sim_server: Any) -> AsyncIterator[tuple[RobotDriver, RecordingProxy]]:
    async with RecordingProxy(sim_server.ports["dashboard"], sim_server.ports["feedback"]) as proxy:
        r = robot_settings.robot.model_copy(
            update={"dashboard_port": proxy.ports["dashboard"], "feedback_port": proxy.ports["feedback"]}
        )
        d = build_driver(robot_settings.model_copy(update={"robot": r}))
        await d.start()
        await d.enable()
        yield d, proxy
        await d.close()
        await d.client.close()


def _stall(sim: Any, driver: RobotDriver, after_targets: int, executed: int | None = None) -> list[int]:
    """A listener that freezes the host (the driver's event loop) once ``after_targets`` ServoJ have
    gone out, until the controller has gone on by ``executed`` targets (its command id) or, with None,
    has run out of targets and rests (its own state, read in-process). Returns how many it went on."""
    went: list[int] = []

    def listener(fb: FeedbackState) -> None:
        monitor = driver._monitor
        if went or not isinstance(monitor, StreamMonitor) or monitor.targets_sent < after_targets:
            return
        with sim.lock:
            start = sim.controller.current_cmd_id
        deadline = time.monotonic() + 30.0  # a safety net only: the controller's own progress ends it
        while time.monotonic() < deadline:
            with sim.lock:
                now, mode = sim.controller.current_cmd_id, sim.controller.mode
            if mode == RobotMode.ENABLE or (executed is not None and now - start >= executed):
                went.append(now - start)
                return
            time.sleep(0.002)  # the stalled host: the loop stands still while the controller runs
        went.append(-1)

    driver.client.add_listener(listener)
    return went


@pytest.mark.integration
async def test_a_host_stall_shorter_than_the_look_ahead_keeps_the_stream_at_speed(proxied, sim_server):
    # the default look-ahead (10 targets, 0.3 s) outlasts a stall of 5 targets (150 ms) with the send
    # margin to spare; at 4 such a stall resumed streams from rest on a quiet machine (3 in 20 trials)
    driver, proxy = proxied
    assert driver.settings.robot.servo_lookahead == 10
    lim = JointLimits.from_spec(driver.spec, 1.0, 1.0)
    q0 = driver.joint_positions()
    goal = q0 + np.deg2rad([50, 0, 0, 0, 0, 0])
    traj = quintic_move(q0, goal, joint_names=driver.spec.joint_names, limits=lim)
    went = _stall(sim_server, driver, int(traj.duration / PERIOD) // 2, executed=5)
    res = await driver.execute_trajectory(traj, PERIOD)
    assert went == [5]  # the host stood still while the controller ran on 5 targets
    assert res.resumed == 0 and driver.stream_resumes == 0
    assert np.max(np.abs(res.final_q - goal)) < driver.settings.robot.goal_tolerance_rad
    bad, n, examples = limit_violations(proxy.commands, driver.limits)
    assert n > 10 and bad == 0, examples


@pytest.mark.integration
async def test_a_stream_that_ran_dry_resumes_from_rest_and_nothing_on_the_wire_is_a_step(proxied, sim_server):
    driver, proxy = proxied
    lim = JointLimits.from_spec(driver.spec, 1.0, 1.0)
    q0 = driver.joint_positions()
    goal = q0 + np.deg2rad([50, 0, 0, 0, 0, 0])
    traj = quintic_move(q0, goal, joint_names=driver.spec.joint_names, limits=lim)
    _stall(sim_server, driver, after_targets=int(traj.duration / PERIOD) // 2)  # at full speed
    res = await driver.execute_trajectory(traj, PERIOD)
    assert res.resumed >= 1 and driver.stream_resumes >= 1
    assert np.max(np.abs(res.final_q - goal)) < driver.settings.robot.goal_tolerance_rad
    bad, n, examples = limit_violations(proxy.commands, driver.limits)
    assert n > 10 and bad == 0, examples
    with sim_server.lock:  # the controller never alarmed (no overspeed) and ran the re-timed stream
        assert not sim_server.controller.alarms
