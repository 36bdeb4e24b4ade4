"""The MuJoCo twin of a UR5e cell behind the simulated UR controller: ur_rtde moves the physical
arm, and the flange's tool outputs drive the twin's gripper."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import dashboard_client
import numpy as np
import pytest
import rtde_control
import rtde_io
import rtde_receive

from services.common.sensors import CameraIntrinsics
from services.rtde.codes import URRobotMode
from services.sim.ur.process import PipeCamera, PipeTruth, SimRequest, SimSpec, URSimProcess
from services.sim.ur.server import free_loopback_host

pytestmark = [pytest.mark.integration, pytest.mark.slow]


@pytest.fixture(scope="module")
def twin_sim() -> Iterator[URSimProcess]:
    with URSimProcess(SimSpec("ur5e", free_loopback_host(), twin=True, seed=3)) as sim:
        yield sim


def _wait(r: rtde_receive.RTDEReceiveInterface, pred: Callable[[], bool], controller_s: float) -> None:
    deadline = r.getTimestamp() + controller_s
    while not pred():
        assert r.getTimestamp() < deadline, f"not reached within {controller_s} s of controller time"
        time.sleep(0.001)


def test_ur_rtde_moves_the_twin_arm_and_closes_its_gripper(twin_sim: URSimProcess) -> None:
    host = twin_sim.host
    db = dashboard_client.DashboardClient(host)
    db.connect()
    r = rtde_receive.RTDEReceiveInterface(host)
    db.powerOn()
    db.brakeRelease()
    _wait(r, lambda: r.getRobotMode() == URRobotMode.RUNNING, 5.0)  # power on + brake release: 1 s
    c = rtde_control.RTDEControlInterface(host)
    io = rtde_io.RTDEIOInterface(host)
    try:
        q = np.array(r.getActualQ()) + np.array([0.3, -0.2, 0.2, 0.1, 0.2, 0.3])
        assert c.moveJ(q.tolist(), 1.0, 2.0)
        # the physical arm lags its reference: it settles onto the target on the controller's clock
        _wait(r, lambda: float(np.max(np.abs(np.array(r.getActualQ()) - q))) <= 1e-3, 2.0)
        assert not twin_sim.snapshot()["gripper_closed"]
        opened = twin_sim.snapshot()["gripper_opening_m"]
        assert io.setToolDigitalOut(1, False) and io.setToolDigitalOut(0, True)  # close: DO 0 on
        _wait(r, lambda: (r.getActualDigitalOutputBits() >> 16) & 0b11 == 0b01, 0.5)
        _wait(r, lambda: twin_sim.snapshot()["gripper_opening_m"] < opened - 0.02, 2.0)
        assert twin_sim.snapshot()["gripper_closed"]
    finally:
        c.stopScript()
        c.disconnect()
        io.disconnect()
        r.disconnect()
        db.disconnect()


def test_the_pipe_carries_the_twins_camera_scene_reset_and_ground_truth(twin_sim: URSimProcess) -> None:
    camera = PipeCamera(twin_sim)
    frame = camera.capture()
    assert frame.color.shape == (camera.intrinsics.height, camera.intrinsics.width, 3)
    assert frame.depth.shape == frame.color.shape[:2] and int(frame.depth.max()) > 0  # the table seen
    truth = PipeTruth(twin_sim)
    assert truth.scene_record().seed == 3
    assert not truth.rod_standing().success  # the rod lies on the table as laid out
    twin_sim.reset_scene(4)
    assert truth.scene_record().seed == 4
    assert frame.seq >= 1 and camera.capture().seq == 1  # the new scene's own camera renders it


def test_a_late_answer_is_never_taken_for_the_next_request(twin_sim: URSimProcess) -> None:
    with pytest.raises(TimeoutError):
        twin_sim.request(SimRequest.CAPTURE, timeout_s=0.0)  # a render takes longer than no time
    # the frame that comes late is dropped: the next request on that pipe gets its own answer
    assert isinstance(twin_sim.intrinsics(), CameraIntrinsics)
