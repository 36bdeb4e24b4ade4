"""ur_rtde's RTDEControlInterface drives the simulated UR controller: its control script is
accepted and its register protocol answered (moveJ, moveL, servoJ, stopJ, setTcp, protective stop).
Every wait is on the controller's clock (the RTDE ``timestamp``), with a deadline."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import dashboard_client
import numpy as np
import pytest
import rtde_control
import rtde_receive

from services.rtde.codes import RuntimeState, SafetyMode, URRobotMode
from services.sim.ur.process import URSimProcess

pytestmark = pytest.mark.integration

POLL_S = 0.001  # how often the test looks at ur_rtde's newest state (it updates at 500 Hz)


class Arm:
    def __init__(self, sim: URSimProcess):
        self.sim = sim
        self.db = dashboard_client.DashboardClient(sim.host)
        self.db.connect()
        self.r = rtde_receive.RTDEReceiveInterface(sim.host)
        self.power_up()
        self.c = rtde_control.RTDEControlInterface(sim.host)

    def power_up(self) -> None:
        self.db.powerOn()
        self.db.brakeRelease()
        self.wait(lambda: self.r.getRobotMode() == URRobotMode.RUNNING, 2.0)

    def wait(self, pred: Callable[[], bool], controller_s: float) -> float:
        """Until ``pred`` holds; fails once the controller's clock ran ``controller_s`` past now."""
        deadline = self.r.getTimestamp() + controller_s
        while not pred():
            now = self.r.getTimestamp()
            assert now < deadline, f"not reached within {controller_s} s of controller time"
            time.sleep(POLL_S)
        return float(self.r.getTimestamp())

    def fresh_q(self) -> np.ndarray:
        """The joints from a package stamped after this call (not the one before it)."""
        t = self.r.getTimestamp()
        self.wait(lambda: self.r.getTimestamp() > t, 0.1)
        return np.array(self.r.getActualQ())

    def close(self) -> None:
        self.c.stopScript()
        self.c.disconnect()
        self.r.disconnect()
        self.db.disconnect()


@pytest.fixture(scope="module")
def arm(ur_sim: URSimProcess) -> Iterator[Arm]:
    a = Arm(ur_sim)
    yield a
    a.close()


def test_control_interface_connects_and_its_script_runs(arm: Arm) -> None:
    assert arm.c.isConnected()
    assert arm.c.isProgramRunning()
    # the receive interface's newest package may predate the control interface's (a loaded machine)
    arm.wait(lambda: arm.r.getRuntimeState() == RuntimeState.PLAYING, 0.5)
    assert "program 'rtde_control' started" in arm.sim.events()


def test_movej_reaches_its_target(arm: Arm) -> None:
    q = arm.fresh_q() + np.array([0.4, -0.2, 0.3, 0.1, -0.1, 0.5])
    assert arm.c.moveJ(q.tolist(), 1.0, 3.0)  # synchronous: returns when the script signals done
    assert np.max(np.abs(arm.fresh_q() - q)) <= 1e-3
    assert np.max(np.abs(arm.r.getActualQd())) < 1e-9


def test_movel_keeps_the_tcp_on_the_line(arm: Arm) -> None:
    start = np.array(arm.r.getActualTCPPose())
    goal = start.copy()
    goal[:3] += [0.08, -0.05, -0.06]
    assert arm.c.moveL(goal.tolist(), 0.25, 1.0, True)  # asynchronous: sample while it moves
    off_line = []
    arm.wait(lambda: arm.c.getAsyncOperationProgressEx().isAsyncOperationRunning(), 0.1)
    while arm.c.getAsyncOperationProgressEx().isAsyncOperationRunning():
        p = np.array(arm.r.getActualTCPPose())[:3]
        d = goal[:3] - start[:3]
        s = np.clip(np.dot(p - start[:3], d) / np.dot(d, d), 0.0, 1.0)
        off_line.append(float(np.linalg.norm(p - (start[:3] + s * d))))
        time.sleep(POLL_S)
    assert len(off_line) > 20  # it was watched while it moved
    assert max(off_line) < 1e-3
    arm.fresh_q()
    assert np.allclose(np.array(arm.r.getActualTCPPose())[:3], goal[:3], atol=1e-6)


def test_a_servoj_stream_is_followed(arm: Arm) -> None:
    q0 = arm.fresh_q()
    # 250 targets, one per 2 ms of the client's clock, each to be reached in 50 ms (servoJ's ``time``):
    # gentle enough that a sim stalled by a busy machine while the client goes on streaming is
    # still asked for less than the joint speed limit when it catches up
    targets = [q0 + np.array([0.1 * np.sin(np.pi * k / 250), 0, 0, 0, 0, 0]) for k in range(1, 251)]
    seen = []
    for q in targets:
        t_cycle = arm.c.initPeriod()
        assert arm.c.servoJ(q.tolist(), 0.5, 0.5, 0.05, 0.1, 300), arm.sim.events()
        seen.append(arm.r.getActualQ()[0])
        arm.c.waitPeriod(t_cycle)
    arm.wait(lambda: abs(arm.r.getActualQ()[0] - targets[-1][0]) < 1e-9, 0.5)
    assert arm.c.servoStop(2.0)
    lo, hi = min(q[0] for q in targets), max(q[0] for q in targets)
    assert min(seen) >= min(lo, q0[0]) - 1e-9 and max(seen) <= hi + 1e-9  # never past the stream
    assert max(seen) > q0[0] + 0.05  # and it did follow it out
    end = arm.fresh_q()
    assert np.allclose(end, targets[-1], atol=1e-6)


def test_stopj_stops_an_async_move_short_of_its_target(arm: Arm) -> None:
    q0 = arm.fresh_q()
    far = q0 + np.array([1.0, 0, 0, 0, 0, 0])
    assert arm.c.moveJ(far.tolist(), 0.5, 1.0, True)
    arm.wait(lambda: arm.r.getActualQ()[0] > q0[0] + 0.1, 2.0)
    arm.c.stopJ(4.0, False)  # returns nothing; synchronous: back once the script is done
    stopped = arm.fresh_q()
    assert stopped[0] < far[0] - 0.2  # short of the target
    assert np.max(np.abs(arm.r.getActualQd())) < 1e-9
    t = arm.r.getTimestamp()
    arm.wait(lambda: arm.r.getTimestamp() > t + 0.05, 1.0)
    assert np.allclose(arm.fresh_q(), stopped)  # and stays stopped
    assert not arm.c.getAsyncOperationProgressEx().isAsyncOperationRunning()


def test_speedj_ramps_to_its_speed_and_speed_stop_brings_it_to_rest(arm: Arm) -> None:
    q0 = arm.fresh_q()
    assert arm.c.speedJ([0.0, 0.0, 0.0, 0.0, 0.0, 0.4], 2.0, 0.008)  # real-time: returns at once
    arm.wait(lambda: abs(arm.r.getActualQd()[5] - 0.4) < 1e-9, 1.0)  # 0.2 s ramp at 2 rad/s²
    assert arm.c.speedStop(4.0)
    arm.wait(lambda: max(abs(v) for v in arm.r.getActualQd()) < 1e-9, 1.0)
    end = arm.fresh_q()
    assert end[5] > q0[5] + 0.02 and np.allclose(end[:5], q0[:5])  # only wrist 3 turned, forward


def test_set_tcp_moves_the_reported_tcp_pose(arm: Arm) -> None:
    flange = np.array(arm.r.getActualTCPPose())
    assert arm.c.setTcp([0, 0, 0.15, 0, 0, 0])
    arm.fresh_q()
    tcp = np.array(arm.r.getActualTCPPose())
    assert abs(np.linalg.norm(tcp[:3] - flange[:3]) - 0.15) < 1e-9
    assert arm.c.setTcp([0, 0, 0, 0, 0, 0])
    assert arm.c.setPayload(0.5, [0, 0, 0.05])


def test_a_target_beyond_a_joint_limit_ends_in_a_protective_stop(arm: Arm) -> None:
    q0 = arm.fresh_q()
    bad = q0.copy()
    bad[2] = 3.5  # the elbow's limit is ±π
    assert not arm.c.moveJ(bad.tolist(), 1.0, 1.0)  # ur_rtde: the command failed
    # the receive side reports it from the next package on (its newest one may predate the stop)
    arm.wait(lambda: arm.r.getSafetyMode() == SafetyMode.PROTECTIVE_STOP, 0.5)
    assert arm.r.isProtectiveStopped()
    assert arm.db.safetystatus() == "Safetystatus: PROTECTIVE_STOP"
    assert any("elbow_joint" in e and "joint position limit" in e for e in arm.sim.events())
    assert np.allclose(arm.fresh_q(), q0)  # nothing moved
    # unlocking is refused until the configured delay has passed on the controller's clock
    arm.wait(lambda: _unlock(arm.db) == "Protective stop releasing", 2.0)
    arm.wait(lambda: arm.r.getSafetyMode() == SafetyMode.NORMAL, 0.1)
    assert arm.c.reuploadScript()
    arm.wait(lambda: arm.c.isProgramRunning(), 1.0)
    assert arm.c.moveJ((q0 + 0.05).tolist(), 1.0, 1.0)


def test_a_servoj_target_too_fast_to_reach_is_a_protective_stop(arm: Arm) -> None:
    q0 = arm.fresh_q()
    jump = q0 + np.array([0, 0, 0, 0, 0, 0.5])  # 0.5 rad in 8 ms: 62 rad/s
    arm.c.servoJ(jump.tolist(), 0.5, 0.5, 0.008, 0.1, 300)
    arm.wait(lambda: arm.r.getSafetyMode() == SafetyMode.PROTECTIVE_STOP, 0.5)
    assert any("wrist_3_joint" in e and "joint speed limit" in e for e in arm.sim.events())
    assert np.allclose(arm.fresh_q(), q0)
    arm.wait(lambda: _unlock(arm.db) == "Protective stop releasing", 2.0)
    assert arm.c.reuploadScript()


def _unlock(db: dashboard_client.DashboardClient) -> str:
    db.send("unlock protective stop\n")
    return str(db.receive())
