"""The vision CLI commands (typer) and the gRPC robot adapter used by `calibrate`."""

from __future__ import annotations

import asyncio
import re
import types

import numpy as np
import pytest
from pickplace.v1 import robot_pb2
from typer.testing import CliRunner

from services.apps.calibration_cli import GrpcCalibrationRobot
from services.apps.cli import app
from services.common.camera_pose import read_calibration
from services.common.errors import IKFailureError
from services.common.settings import load_settings
from services.kinematics.analytic import fk
from services.kinematics.robot_models import get_robot
from services.vision.replay import record_frames
from services.vision.synthetic import NoiseModel, render_scene
from services.vision.synthetic_scenes import random_scene

runner = CliRunner()


@pytest.fixture
def calibration_file(tmp_path, monkeypatch):  # type: ignore[no-untyped-def]
    path = tmp_path / "calibration.yaml"
    monkeypatch.setenv("PICKPLACE_VISION__CALIBRATION__FILE", str(path))
    return path


def test_calibrate_manual_writes_a_validated_file(calibration_file):
    result = runner.invoke(
        app, ["calibrate-manual", "--xyz", "0.9", "0.0", "0.65", "--rpy", "-145", "0", "90"]
    )
    assert result.exit_code == 0, result.output
    saved = read_calibration(calibration_file)
    np.testing.assert_allclose(saved.T_base_camera[:3, 3], [0.9, 0.0, 0.65])
    assert saved.method == "manual"
    bad = runner.invoke(app, ["calibrate-manual", "--xyz", "900", "0", "650", "--rpy", "0", "0", "0"])
    assert bad.exit_code == 1 and "units" in bad.output


def test_vision_detect_on_a_recording(tmp_path, calibration_file):
    scene = random_scene(41, n_rods=1, cube_colors=("red",))

    class Cam:
        intrinsics = scene.intrinsics

        def capture(self):  # type: ignore[no-untyped-def]
            return render_scene(scene, NoiseModel(), seed=1).frame

        def close(self) -> None:
            pass

    record_frames(Cam(), tmp_path / "rec", 1)
    # with the scene's true camera pose as the calibration, results print in the base frame
    T = scene.T_base_camera
    from scipy.spatial.transform import Rotation

    rpy = Rotation.from_matrix(T[:3, :3]).as_euler("xyz", degrees=True)
    assert (
        runner.invoke(
            app, ["calibrate-manual", "--xyz", *map(str, T[:3, 3]), "--rpy", *map(str, rpy)]
        ).exit_code
        == 0
    )
    overlay = tmp_path / "o.jpg"
    result = runner.invoke(app, ["vision-detect", str(tmp_path / "rec"), "--overlay", str(overlay)])
    assert result.exit_code == 0, result.output
    assert "rod #1" in result.output and "red cube" in result.output and "base" in result.output
    row = next(line for line in result.output.splitlines() if "rod #1" in line)
    xyz = [float(v) for v in re.findall(r"-?\d+\.\d{4}", row)[:3]]
    np.testing.assert_allclose(xyz, scene.rods[0].center, atol=0.003)  # printed in the base frame
    assert overlay.read_bytes()[:2] == b"\xff\xd8"
    missing = runner.invoke(app, ["vision-detect", str(tmp_path / "nothing-here")])
    assert missing.exit_code == 1 and "CameraConnectionError" in missing.output


def test_grpc_robot_adapter_moves_by_ik_and_reports_fk():
    spec = get_robot("nova5")
    q_home = np.deg2rad([0.0, 0.0, 90.0, 0.0, -90.0, 0.0])
    sent: list[np.ndarray] = []

    class Stub:
        q = q_home.copy()

        async def GetJointStates(self, request, **_kw):  # type: ignore[no-untyped-def]
            return types.SimpleNamespace(position=list(self.q))

        async def MoveJoints(self, request, **_kw):  # type: ignore[no-untyped-def]
            assert isinstance(request, robot_pb2.MoveJointsRequest) and request.speed_ratio == 15
            self.q = np.asarray(request.positions)
            sent.append(self.q)
            return robot_pb2.MoveResponse(success=True)

    robot = GrpcCalibrationRobot(load_settings("sim"), speed_ratio=15, settle_s=0.0, stub=Stub())
    target = fk(spec, np.deg2rad([20.0, 10.0, 80.0, -10.0, -80.0, 30.0]))

    async def go() -> np.ndarray:
        await robot.move_to_pose(target)
        return await robot.get_pose()

    reached = asyncio.run(go())
    np.testing.assert_allclose(reached, target, atol=1e-6)
    assert len(sent) == 1
    far = target.copy()
    far[:3, 3] = [3.0, 0.0, 0.5]
    with pytest.raises(IKFailureError):
        asyncio.run(robot.move_to_pose(far))
