"""``pickplace sim-ur`` serves a simulated UR on the address it is given and stops on SIGINT."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from services.apps.cli import app
from services.common.settings import load_settings
from services.rtde import codec
from services.rtde.codes import MessageType
from services.sim.ur.server import free_loopback_host

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[3]
START_TIMEOUT_S = 60.0  # a cold interpreter imports numpy, scipy and the kinematics first


def test_sim_ur_refuses_a_non_loopback_address() -> None:
    result = CliRunner().invoke(app, ["sim-ur", "--host", "192.0.2.1"])
    assert result.exit_code == 2
    assert "loopback only" in result.output


def test_sim_ur_serves_rtde_and_the_dashboard_until_interrupted() -> None:
    host = free_loopback_host()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "services.apps.ur_cli",
            "sim-ur",
            "--host",
            host,
            "--powered",
            "--model",
            "ur3",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()  # the banner is written once it listens
        assert f"simulated ur3 on {host}" in line, line
        with socket.create_connection((host, 29999), timeout=5) as s:
            f = s.makefile("rw", newline="\n")
            assert f.readline().startswith("Connected: Universal Robots Dashboard Server")
            f.write("robotmode\n")
            f.flush()
            assert f.readline().strip() == "Robotmode: RUNNING"  # --powered
            f.write("get robot model\n")
            f.flush()
            assert f.readline().strip() == "UR3"
        with socket.create_connection((host, 30004), timeout=5) as s:
            s.sendall(codec.request_protocol_version())
            pkg = next(codec.Framer().feed(s.recv(64)))
            assert pkg.type == MessageType.REQUEST_PROTOCOL_VERSION and pkg.payload == b"\x01"
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            assert proc.wait(START_TIMEOUT_S) == 0
        finally:
            if proc.poll() is None:
                proc.kill()


@pytest.mark.slow
async def test_ur_keypose_runs_seed_003s_cycle_through_the_shared_driver(tmp_path: Path) -> None:
    from services.apps.ur_cli import run_ur_keypose

    settings = load_settings(
        "sim",
        config_file=ROOT / "config" / "robots" / "ur3-keypose.yaml",
        overrides={
            "cycle": {"move_duration_s": 0.4, "dwell_s": 0.0},
            "logging": {"file": str(tmp_path / "log")},
        },
    )
    assert (
        settings.robot.model == "ur3" and settings.cycle.poses_deg["home"][1] == -89.9544
    )  # seed 003's -1.57 rad
    report = await run_ur_keypose(settings, cycles=1, twin=False)
    assert report.cycles == 1 and report.moves == len(settings.cycle.sequence)
    assert report.max_position_error_deg < np.rad2deg(1e-3)  # every key pose reached within 1 mrad
