"""The shared RobotDriver on a UR: URLink over ur_rtde against the simulated UR controller (its own
process, its own loopback address). Every safety rule is the driver's; the controller's protective
stop, the e-stop and a pulled cable are reported through it. Waits are on the controller's clock."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Iterator

import numpy as np
import pytest
import pytest_asyncio

from services.common.errors import (
    ConfigurationError,
    ControllerError,
    EmergencyStopError,
    LimitViolationError,
    RobotCommunicationError,
)
from services.common.settings import Settings, load_settings
from services.common.settings.robot import RobotDriverKind
from services.dobot import RobotMode
from services.kinematics.interpolation import quintic_move
from services.robot.driver import RobotDriver
from services.robot.feedback import LinkState
from services.robot.service import build_driver
from services.robot.ur.link import URLink
from services.sim.ur.controller import URControllerConfig
from services.sim.ur.process import SimSpec, URSimProcess
from services.sim.ur.server import free_loopback_host

# one driver for the module (each ur_rtde disconnect sleeps 500 ms): every test leaves it enabled
pytestmark = [pytest.mark.integration, pytest.mark.asyncio(loop_scope="module")]

FAST = URControllerConfig(power_on_s=0.05, brake_release_s=0.05, unlock_delay_s=0.1)


@pytest.fixture(scope="module")
def ur_sim() -> Iterator[URSimProcess]:
    with URSimProcess(SimSpec("ur5e", free_loopback_host(), FAST)) as sim:
        yield sim


def ur_settings(tmp_path: object, host: str) -> Settings:
    return load_settings(
        "sim",
        overrides={
            "logging": {"file": f"{tmp_path}/pickplace.log"},
            "robot": {
                "model": "ur5e",
                "driver": "ur_rtde",
                "host": host,
                "retry_wait_s": 0.05,
                "step_retries": 0,
                "motion_timeout_s": 20.0,
                "reconnect": {"max_attempts": 3, "base_delay_s": 0.05, "max_delay_s": 0.2},
            },
            "gripper": {"tool_outputs": True, "close_do": 1, "open_do": 2, "actuation_time_s": 0.05},
        },
    )


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def driver(
    tmp_path_factory: pytest.TempPathFactory, ur_sim: URSimProcess
) -> AsyncIterator[RobotDriver]:
    d = build_driver(ur_settings(tmp_path_factory.mktemp("ur"), ur_sim.host))
    assert isinstance(d.client, URLink)
    await d.start()
    await d.enable()
    try:
        yield d
    finally:
        await d.client.close()


@pytest.mark.asyncio(loop_scope="module")
async def test_settings_select_the_ur_driver_and_refuse_it_for_a_dobot(tmp_path: object) -> None:
    s = ur_settings(tmp_path, "127.0.0.1")
    assert s.robot.driver is RobotDriverKind.UR_RTDE
    with pytest.raises(ConfigurationError, match="ur_rtde drives a UR"):
        load_settings("sim", overrides={"robot": {"model": "nova5", "driver": "ur_rtde"}})


async def test_feedback_streams_at_500_hz_on_the_controller_clock(driver: RobotDriver) -> None:
    stamps = [(await driver.client.next_feedback()).timestamp_ms for _ in range(100)]
    steps = np.diff(stamps)
    # whole 2 ms control cycles, in order (how many a busy host skips is measured in make bench)
    assert np.all(steps >= 2) and np.all(steps % 2 == 0)
    fb = driver.feedback
    assert fb.robot_mode == RobotMode.ENABLE and fb.enabled and not fb.estop


async def test_move_joints_reaches_its_target(driver: RobotDriver) -> None:
    q = driver.joint_positions() + np.array([0.3, -0.1, 0.2, 0.1, 0.2, -0.3])
    res = await driver.move_joints(q, speed_ratio=80)
    assert np.max(np.abs(res.final_q - q)) <= 1e-3
    res = await driver.move_joints(q + 0.05, linear=True)  # MovL: ur_rtde's moveL_FK
    assert np.max(np.abs(res.final_q - (q + 0.05))) <= 1e-3


async def test_a_trajectory_streams_as_servoj_and_is_followed(driver: RobotDriver) -> None:
    q0 = driver.joint_positions()
    goal = q0 + np.array([0.2, 0.1, -0.1, 0.0, 0.1, 0.2])
    traj = quintic_move(q0, goal, joint_names=driver.spec.joint_names, duration_s=1.0)
    res = await driver.execute_trajectory(traj, servo_period_s=0.02)
    assert np.max(np.abs(res.final_q - goal)) <= 1e-3


async def test_a_target_beyond_a_joint_limit_is_refused_before_anything_is_sent(driver: RobotDriver) -> None:
    q = driver.joint_positions()
    bad = q.copy()
    bad[2] = 3.5
    with pytest.raises(LimitViolationError):
        await driver.move_joints(bad)
    assert np.allclose(driver.joint_positions(), q)


async def test_a_protective_stop_is_reported_clearly_and_recovered(
    driver: RobotDriver, ur_sim: URSimProcess
) -> None:
    link = driver.client
    assert isinstance(link, URLink)
    # past the driver (a raw link command, as a fault would): the controller's safety system stops it
    q = driver.joint_positions()
    bad = q.copy()
    bad[1] = 7.0
    with pytest.raises(ControllerError, match="PROTECTIVE_STOP"):
        rid = await link.mov_j(bad)
        await link.wait_motion_done(rid, 5.0)
    assert driver.feedback.in_error
    assert any("joint position limit" in e for e in ur_sim.events())
    await link.wait_controller_time(FAST.unlock_delay_s)
    await driver.clear_error()
    await driver.enable()
    res = await driver.move_joints(q + 0.02)
    assert np.max(np.abs(res.final_q - (q + 0.02))) <= 1e-3


async def test_the_gripper_drives_the_tool_outputs(driver: RobotDriver) -> None:
    # actual_digital_output_bits: tool outputs are bits 16 and 17 (close = tool DO 0, open = tool DO 1)
    state = await driver.set_gripper(True)
    assert state.closed
    assert (driver.feedback.digital_outputs >> 16) & 0b11 == 0b01
    await driver.set_gripper(False)
    assert (driver.feedback.digital_outputs >> 16) & 0b11 == 0b10


async def test_a_pressed_estop_stops_motion_and_blocks_enable(
    driver: RobotDriver, ur_sim: URSimProcess
) -> None:
    q = driver.joint_positions()
    ur_sim.press_estop(True)
    fb = await driver.client.wait_feedback(lambda f: f.estop, 2.0)
    assert fb.robot_mode == RobotMode.POWER_OFF
    with pytest.raises(EmergencyStopError):
        await driver.move_joints(q + 0.1)
    with pytest.raises(EmergencyStopError):
        await driver.enable()
    ur_sim.press_estop(False)
    await driver.client.wait_feedback(lambda f: not f.estop, 2.0)
    await driver.enable()
    # the software e-stop latches in the link: powered off, enable refused until released
    await driver.emergency_stop()
    assert (await driver.client.next_feedback()).estop
    with pytest.raises(EmergencyStopError):
        await driver.enable()
    await driver.emergency_stop(release=True)
    await driver.enable()
    res = await driver.move_joints(q + 0.05)
    assert np.max(np.abs(res.final_q - (q + 0.05))) <= 1e-3


async def test_a_pulled_cable_is_reported_and_the_link_comes_back(
    driver: RobotDriver, ur_sim: URSimProcess
) -> None:
    link = driver.client
    assert isinstance(link, URLink)
    epoch = link.link_epoch
    # the cable out for 2 s: connections are refused meanwhile, so nothing can come back before it
    cable = asyncio.create_task(asyncio.to_thread(ur_sim.cut_links, 2.0))
    with pytest.raises(RobotCommunicationError):
        for _ in range(5000):  # the loss shows on the next wait; nothing else is judged by time
            await link.next_feedback()
    assert link.link is not LinkState.UP and link.link_epoch == epoch + 1
    with pytest.raises(RobotCommunicationError):
        await driver.move_joints(driver.joint_positions() + 0.05)
    await cable
    while link.link is not LinkState.UP:
        try:
            await link.next_feedback(5.0)
        except RobotCommunicationError:
            continue
    await driver.enable()
    q = driver.joint_positions()
    res = await driver.move_joints(q + 0.05)
    assert np.max(np.abs(res.final_q - (q + 0.05))) <= 1e-3
