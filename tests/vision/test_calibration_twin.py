"""End-to-end eye-to-hand calibration in the twin: it must recover the twin's true camera pose.

The twin (board on the gripper, camera noise on) runs behind the simulated Dobot on loopback; the
robot-driver service drives it through the real client, the calibration moves go through the same
gRPC adapter `pickplace calibrate` uses, and the twin camera renders what the arm did.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from services.apps.calibration_cli import GrpcCalibrationRobot
from services.common.camera_pose import read_calibration
from services.common.frames import invert_transform, make_transform
from services.common.settings import Settings
from services.robot.service import RobotService
from services.sim.app import build_sim_server
from services.sim.twin import ground_truth
from services.sim.twin.calibration_board import CALIBRATION_READY_DEG, board_mount, twin_calibration_settings
from services.sim.twin.camera import TwinCamera
from services.vision.calibrate_workflow import run_calibration
from tests.sim.twin_helpers import twin_settings
from tests.vision.test_calibration import ROT_TOL_DEG, TRANS_TOL_M, pose_error

pytestmark = pytest.mark.integration

N_POSES = 10


def cell_settings() -> Settings:
    s = twin_settings({"cubes": [], "rod": False, "obstacle": False}, robot={"speed_ratio": 100})
    s = twin_calibration_settings(s)
    cal = s.vision.calibration.model_copy(update={"n_poses": N_POSES})
    # sim time runs 3x faster than wall time: same 8 ms ticks, shorter test
    sim = s.sim.model_copy(update={"speed": 3.0, "engine": "twin"})
    return s.model_copy(update={"sim": sim, "vision": s.vision.model_copy(update={"calibration": cal})})


async def test_calibration_in_the_twin_recovers_the_true_camera_pose(tmp_path) -> None:  # type: ignore[no-untyped-def]
    s = cell_settings()
    assert s.sim.twin.calibration_board and s.sim.twin.camera.noise
    X_true = ground_truth.T_base_camera(s.sim.twin.camera)
    # The operator's rough guess (a few cm, a few degrees off): it only aims the board.
    X_guess = X_true @ make_transform(
        Rotation.from_euler("xyz", [2.0, -3.0, 2.0], degrees=True).as_matrix(), [0.03, -0.02, 0.04]
    )
    out = tmp_path / "calibration.yaml"
    server = build_sim_server(
        s, "twin", q0_deg=CALIBRATION_READY_DEG, ports={"dashboard": 0, "feedback": 0, "slow": 0}
    )
    async with server:
        robot_settings = s.robot.model_copy(
            update={"dashboard_port": server.ports["dashboard"], "feedback_port": server.ports["feedback"]}
        )
        s = s.model_copy(update={"robot": robot_settings})
        camera = TwinCamera(server.controller.engine, seed=3)
        try:
            async with RobotService(s, bus=None, grpc_port=0) as svc:
                await svc.driver.enable()
                grpc = s.grpc.model_copy(update={"robot_port": svc.grpc_port})
                async with GrpcCalibrationRobot(
                    s.model_copy(update={"grpc": grpc}), speed_ratio=100, settle_s=0.1
                ) as robot:
                    result, data = await run_calibration(
                        robot, camera, s.vision.calibration, X_guess, out, seed=0
                    )
        finally:
            camera.close()

    assert camera.noise  # the views were noisy, as configured
    assert len(data.observations) >= 8, data.skipped
    dt_m, dr = pose_error(result.T_base_camera, X_true)
    print(
        f"twin calibration: {len(data.observations)} views, error {dt_m * 1e3:.2f} mm, {dr:.3f} deg; "
        f"skipped {data.skipped}"
    )
    assert dt_m <= TRANS_TOL_M and dr <= ROT_TOL_DEG, (dt_m, dr)
    # The board mount is estimated too, and matches the twin's.
    dy_m, dy_deg = pose_error(result.T_gripper_board, board_mount(s.vision.calibration.board, s.gripper))
    assert dy_m <= TRANS_TOL_M and dy_deg <= ROT_TOL_DEG, (dy_m, dy_deg)
    # The file the vision service reads holds the same pose.
    saved = read_calibration(out)
    np.testing.assert_allclose(saved.T_base_camera, result.T_base_camera, atol=1e-9)
    assert pose_error(invert_transform(saved.T_base_camera) @ X_true, np.eye(4))[0] <= TRANS_TOL_M


def test_calibrate_cli_with_the_twin_source_writes_the_true_pose(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    from typer.testing import CliRunner

    from services.apps.cli import app
    from services.common.settings import load_settings

    monkeypatch.setenv("PICKPLACE_SIM__SPEED", "3")
    monkeypatch.setenv("PICKPLACE_ROBOT__SPEED_RATIO", "100")
    out = tmp_path / "calibration.yaml"
    result = CliRunner().invoke(
        app,
        [
            "calibrate",
            "--profile",
            "sim",
            "--source",
            "twin",
            "--poses",
            "8",
            "--speed",
            "100",
            "--out",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    X_true = ground_truth.T_base_camera(load_settings("sim").sim.twin.camera)
    dt_m, dr = pose_error(read_calibration(out).T_base_camera, X_true)
    assert dt_m <= TRANS_TOL_M and dr <= ROT_TOL_DEG, (dt_m, dr, result.output)
