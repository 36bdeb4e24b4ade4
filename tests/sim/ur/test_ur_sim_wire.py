"""The simulated UR controller over real loopback sockets: RTDE (our codec and ur_rtde as clients)
and the dashboard server, answering as a real e-Series controller words it."""

from __future__ import annotations

import socket

import dashboard_client
import numpy as np
import pytest
import rtde_receive

from services.kinematics import analytic
from services.kinematics.robot_models import get_robot
from services.rtde import codec
from services.rtde.codes import MessageType, SafetyMode, URRobotMode
from services.rtde.fields import FieldType
from services.rtde.poses import pose_to_transform
from services.sim.ur.process import URSimProcess
from tests.sim.ur.conftest import FAST

pytestmark = pytest.mark.integration

Q0 = np.array(FAST.q0)


def _read(sock: socket.socket, framer: codec.Framer, want: int) -> codec.Package:
    while True:
        for pkg in framer.feed(sock.recv(65536)):
            if pkg.type == want:
                return pkg


def test_rtde_data_packages_come_every_control_cycle_on_the_controller_clock(ur_sim: URSimProcess) -> None:
    with socket.create_connection((ur_sim.host, 30004), timeout=5) as s:
        f = codec.Framer()
        s.sendall(codec.request_protocol_version())
        assert _read(s, f, MessageType.REQUEST_PROTOCOL_VERSION).payload == b"\x01"
        s.sendall(codec.pack(MessageType.GET_URCONTROL_VERSION))
        major, minor, _, _ = codec.parse_controller_version(
            _read(s, f, MessageType.GET_URCONTROL_VERSION).payload
        )
        assert (major, minor) == (5, 11)  # e-Series: 500 Hz
        s.sendall(codec.setup_outputs_request(["timestamp", "actual_q", "robot_mode", "no_such_field"], 500))
        rid, words = codec.parse_setup_reply(_read(s, f, MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS).payload)
        assert rid == 0 and words[-1] == "NOT_FOUND"  # refused, naming the unknown field
        s.sendall(codec.setup_outputs_request(["timestamp", "actual_q", "robot_mode"], 500))
        rid, words = codec.parse_setup_reply(_read(s, f, MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS).payload)
        assert rid == 1 and words == ("DOUBLE", "VECTOR6D", "INT32")
        recipe = codec.Recipe(1, ("timestamp", "actual_q", "robot_mode"), tuple(codec_types(words)))
        s.sendall(codec.pack(MessageType.CONTROL_PACKAGE_START))
        assert _read(s, f, MessageType.CONTROL_PACKAGE_START).payload == b"\x01"
        stamps = []
        while len(stamps) < 200:
            for pkg in f.feed(s.recv(65536)):
                if pkg.type == MessageType.DATA_PACKAGE:
                    v = recipe.unpack(pkg.payload)
                    stamps.append(v["timestamp"])
                    assert np.allclose(v["actual_q"], Q0)
        s.sendall(codec.pack(MessageType.CONTROL_PACKAGE_PAUSE))
    # one package per 2 ms control cycle: the controller's own clock, no cycle skipped or repeated
    assert np.allclose(np.diff(stamps), 0.002, atol=1e-9)


def codec_types(words: tuple[str, ...]) -> list[FieldType]:
    return [FieldType(w) for w in words]


def test_ur_rtde_receive_reads_joints_tcp_pose_mode_and_an_advancing_clock(ur_sim: URSimProcess) -> None:
    r = rtde_receive.RTDEReceiveInterface(ur_sim.host)  # every default variable of ur_rtde 1.6.5
    try:
        assert r.isConnected()
        assert np.allclose(r.getActualQ(), Q0)
        spec = get_robot("ur5e")
        T = pose_to_transform(np.array(r.getActualTCPPose()))
        assert np.allclose(T, analytic.fk(spec, Q0), atol=1e-9)
        assert r.getRobotMode() in (URRobotMode.POWER_OFF, URRobotMode.IDLE, URRobotMode.RUNNING)
        assert r.getSafetyMode() == SafetyMode.NORMAL
        t0 = r.getTimestamp()
        seen = [t0]
        while seen[-1] < t0 + 0.1:
            seen.append(r.getTimestamp())
        # every reading is a whole number of 2 ms cycles on from the first: 500 Hz packages
        cycles = (np.array(seen) - t0) / 0.002
        assert np.allclose(cycles, np.round(cycles), atol=1e-6)
        assert np.all(np.diff(seen) >= 0)
    finally:
        r.disconnect()


def test_dashboard_answers_in_a_real_controllers_words(ur_sim: URSimProcess) -> None:
    db = dashboard_client.DashboardClient(ur_sim.host)
    db.connect()
    try:
        assert db.polyscopeVersion() == "5.11.1.108318"
        db.send("PolyscopeVersion\n")
        assert db.receive() == "URSoftware 5.11.1.108318 (Nov 03 2021)"
        db.powerOff()
        assert db.robotmode() == "Robotmode: POWER_OFF"
        db.send("power on\n")
        assert db.receive() == "Powering on"
        db.send("brake release\n")
        assert db.receive() == "Brake releasing"
        assert db.safetystatus() == "Safetystatus: NORMAL"
        assert db.isInRemoteControl()
        assert db.getSerialNumber().isdigit()
        assert db.getRobotModel() == "UR5"
        db.send("unlock protective stop\n")
        assert db.receive() == "Protective stop releasing"  # nothing to unlock is not an error
        db.send("stop\n")
        assert db.receive() == "Stopped"  # also with no program running, as ur_rtde expects
        db.send("play\n")
        assert db.receive() == "Failed to execute: play"  # no program loaded
        db.send("fly\n")
        assert db.receive() == "could not understand: 'fly'"
    finally:
        db.disconnect()
