"""Execution monitoring: measured joints against the plan during and after every motion, with a
simulated controller whose arm lags, sticks or settles off its reference (``TrackingFault``).

Over real sockets; judged by the driver's error (joint and deviation named), the controller's command
log and state."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import numpy as np
import pytest

from services.common.errors import ExecutionError, PathDeviationError
from services.dobot import RobotMode
from services.kinematics.interpolation import quintic_move
from services.kinematics.trajectory import JointLimits, JointTrajectory
from services.robot.driver import RobotDriver
from services.robot.monitor import StreamMonitor, goal_deviation, path_deviation
from services.robot.service import build_driver
from services.sim.controller import FaultKind, TrackingFault
from tests.conftest import HOME

PERIOD = 0.03


@pytest.fixture
async def driver(robot_settings) -> AsyncIterator[RobotDriver]:  # type: ignore[no-untyped-def]
    d = build_driver(robot_settings)
    await d.start()
    await d.enable()
    yield d
    await d.close()
    await d.client.close()


def _move(d: RobotDriver, dq_deg: list[float]) -> JointTrajectory:
    lim = JointLimits.from_spec(d.spec, velocity_scale=0.5, acceleration_scale=0.5)
    goal = d.joint_positions() + np.deg2rad(dq_deg)
    return quintic_move(d.joint_positions(), goal, joint_names=d.spec.joint_names, limits=lim)


def _inject(sim: Any, fault: TrackingFault | None) -> None:
    with sim.lock:
        sim.controller.tracking_fault = fault


def _stopped_by_the_driver(sim: Any) -> bool:
    with sim.lock:
        return any(text == "Stop()" for _, text in sim.controller.command_log)


@pytest.mark.integration
async def test_an_arm_that_lags_its_trajectory_is_stopped_naming_the_joint(driver, sim_server):
    traj = _move(driver, [0, 40, 0, 0, 0, 0])
    _inject(sim_server, TrackingFault(FaultKind.LAG, lag_s=0.3))
    # a PathDeviationError (an ExecutionError): the task takes one at a grasp approach for a contact
    with pytest.raises(PathDeviationError, match=r"joint 2 is -\d+\.\d+° off the planned trajectory"):
        await driver.execute_trajectory(traj, PERIOD)
    assert driver.monitor_trips == 1 and _stopped_by_the_driver(sim_server)
    fb = await driver.client.wait_feedback(lambda f: f.robot_mode == RobotMode.ENABLE, 2.0)
    assert np.rad2deg(fb.q[1]) < 35.0  # stopped on the way, not at the goal
    tol = driver.settings.robot.path_tolerance_rad
    assert tol < abs(float(str(driver.last_fault).split(" is ")[1].split("°")[0])) * np.pi / 180 < 2 * tol


@pytest.mark.integration
async def test_a_stuck_joint_is_caught_during_the_motion(driver, sim_server):
    traj = _move(driver, [30, 0, 0, 0, 0, 0])
    _inject(sim_server, TrackingFault(FaultKind.STUCK, joint=0))
    with pytest.raises(ExecutionError, match="joint 1 is -"):
        await driver.execute_trajectory(traj, PERIOD)
    assert _stopped_by_the_driver(sim_server)


@pytest.mark.integration
async def test_an_arm_that_settles_off_its_goal_fails_the_goal_check(driver, sim_server):
    traj = _move(driver, [0, 0, 20, 0, 0, 0])
    # 1.15° off: inside the path tolerance (2.9°), outside the goal tolerance (0.29°); a path deviation
    # at its end, which the task takes at a grasp approach for fingers held off by the object's edge
    _inject(sim_server, TrackingFault(FaultKind.OFFSET, joint=2, offset_rad=0.02))
    with pytest.raises(PathDeviationError, match=r"trajectory ended with joint 3 is \+1\.15° off its goal"):
        await driver.execute_trajectory(traj, PERIOD)
    assert driver.monitor_trips == 1 and _stopped_by_the_driver(sim_server)
    with pytest.raises(PathDeviationError, match=r"MoveJoints ended with joint 3 is \+1\.15° off its goal"):
        await driver.move_joints(HOME, speed_ratio=100)
    # healthy again: both pass their checks
    _inject(sim_server, None)
    res = await driver.move_joints(HOME, speed_ratio=100)
    assert np.allclose(res.final_q, HOME, atol=1e-6)
    await driver.execute_trajectory(_move(driver, [0, 0, 20, 0, 0, 0]), PERIOD)


@pytest.mark.integration
async def test_a_movej_whose_arm_lags_the_controllers_reference_is_stopped(driver, sim_server):
    _inject(sim_server, TrackingFault(FaultKind.LAG, lag_s=0.3))
    with pytest.raises(ExecutionError, match=r"joint 1 is -.*off the controller's reference"):
        await driver.move_joints(HOME + np.deg2rad([60, 0, 0, 0, 0, 0]), speed_ratio=100)
    assert driver.monitor_trips == 1 and _stopped_by_the_driver(sim_server)


@pytest.mark.integration
async def test_a_healthy_arm_passes_with_its_deviation_recorded(driver):
    traj = _move(driver, [20, -10, 15, 0, 10, 0])
    res = await driver.execute_trajectory(traj, PERIOD)
    assert np.allclose(res.final_q, traj.positions[-1], atol=1e-6)
    assert driver.monitor_trips == 0 and driver.watchdog_trips == 0


# ---------------------------------------------------------------------- the pure core
def test_path_deviation_is_the_distance_to_the_closest_segment():
    a, b, c = np.zeros(6), np.r_[1.0, 0, 0, 0, 0, 0], np.r_[1.0, 1.0, 0, 0, 0, 0]
    on = np.r_[0.5, 0, 0, 0, 0, 0]
    assert path_deviation(on, [a, b, c]).rad == 0.0
    off = np.r_[1.0, 0.5, 0.0, 0.2, 0, 0]
    dev = path_deviation(off, [a, b, c])
    assert dev.joint == 3 and np.isclose(dev.rad, 0.2)
    assert goal_deviation(np.r_[0, 0, -0.3, 0, 0, 0], a).describe() == "joint 3 is -17.19° off"


class _Fb:
    def __init__(self, stamp_ms: int, current_id: int, q: np.ndarray, mode: int = RobotMode.RUNNING):
        self.timestamp_ms, self.current_command_id, self.q, self.robot_mode = stamp_ms, current_id, q, mode


def test_starvation_needs_both_clocks_so_a_fast_simulator_is_not_a_stalled_host():
    wall = [0.0]
    m = StreamMonitor(np.zeros(6), 0.03, 0.05, 0.25, wall_s=lambda: wall[0])
    m.sent(np.zeros(6), 1)
    assert m.on_feedback(_Fb(1000, 1, np.zeros(6))) is None  # running the newest target
    # the controller's clock runs 10 s on while the host's barely moved (a sim at N×): no trip
    assert m.on_feedback(_Fb(11_000, 1, np.zeros(6))) is None  # type: ignore[arg-type]
    wall[0] = 0.2
    assert m.on_feedback(_Fb(11_008, 1, np.zeros(6))) is None  # type: ignore[arg-type]
    wall[0] = 0.29
    fault = m.on_feedback(_Fb(11_016, 1, np.zeros(6)))  # type: ignore[arg-type]
    assert fault is not None and "ServoJ watchdog" in str(fault)
    # a stream that ends may run dry: not owed, no trip
    m2 = StreamMonitor(np.zeros(6), 0.03, 0.05, 0.25, wall_s=lambda: wall[0])
    m2.sent(np.zeros(6), 1)
    m2.owed = False
    m2.on_feedback(_Fb(0, 1, np.zeros(6)))  # type: ignore[arg-type]
    wall[0] = 100.0
    assert m2.on_feedback(_Fb(100_000, 1, np.zeros(6), RobotMode.ENABLE)) is None  # type: ignore[arg-type]


def test_the_clock_rate_is_the_controllers_time_per_host_time():
    from services.robot.monitor import ClockRate

    r = ClockRate(window_s=1.0)
    assert r.on_feedback(0, 0) == 1.0  # not enough yet
    for k in range(1, 40):  # a controller slowed to 0.4×: 8 ms of its time per 20 ms of the host
        rate = r.on_feedback(8 * k, 20_000_000 * k)
    assert abs(rate - 0.4) < 1e-9
    r2 = ClockRate(window_s=1.0)
    for k in range(0, 100):
        rate = r2.on_feedback(32 * k, 8_000_000 * k)
    assert abs(rate - 4.0) < 1e-9
