"""Typer commands of the camera calibration, for the ``pickplace`` app to mount (``app.add_typer(...)``).

- ``calibrate``: the automatic eye-to-hand calibration — the robot-driver service moves the
  ChArUco board through generated poses, the camera sees it, the solve writes the calibration file;
- ``calibrate-manual``: the seed 001 PoC path — a measured camera pose written as the calibration;
- ``calibration-check``: the quick drift check against the current calibration.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer
from rich.console import Console
from rich.progress import Progress

from services.apps.vision_cli import ProfileOpt, SourceOpt, _calibration_path, _fail, _settings, open_camera
from services.common.errors import (
    ConfigurationError,
    ExecutionError,
    RobotError,
)
from services.common.sensors import Camera
from services.common.settings import Settings

if TYPE_CHECKING:
    import grpc.aio
    from pickplace.v1.robot_pb2_grpc import RobotControllerStub

app = typer.Typer(
    help="Camera calibration: automatic (ChArUco board), manual, drift check.", no_args_is_help=True
)
console = Console()


class GrpcCalibrationRobot:
    """The robot-driver service as a CalibrationRobot: IK (closed form) + MoveJoints, FK of measured joints."""

    def __init__(
        self,
        settings: Settings,
        speed_ratio: int = 20,
        settle_s: float = 0.5,
        stub: RobotControllerStub | None = None,
    ):
        from services.kinematics.robot_models import get_robot

        self.settings = settings
        self.spec = get_robot(settings.robot.model)
        self.speed_ratio = speed_ratio
        self.settle_s = settle_s
        self._stub = stub
        self._channel: grpc.aio.Channel | None = None

    async def __aenter__(self) -> GrpcCalibrationRobot:
        if self._stub is None:
            from pickplace.v1 import robot_pb2_grpc

            from services.common.grpc_util import cell_token, channel

            self._channel = channel(
                self.settings.grpc.host, self.settings.grpc.robot_port, cell_token(self.settings)
            )
            self._stub = robot_pb2_grpc.RobotControllerStub(self._channel)
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._channel is not None:
            await self._channel.close()

    def _robot(self) -> RobotControllerStub:
        if self._stub is None:
            raise RuntimeError("GrpcCalibrationRobot is used inside `async with` only")
        return self._stub

    async def _joints(self) -> np.ndarray:
        from pickplace.v1 import robot_pb2

        from services.common.grpc_util import rpc_errors

        with rpc_errors():
            js = await self._robot().GetJointStates(
                robot_pb2.GetJointStatesRequest(),
                timeout=self.settings.grpc.request_timeout_s,
            )
        return np.asarray(js.position, dtype=float)

    async def move_to_pose(self, T_base_gripper: np.ndarray) -> None:
        from pickplace.v1 import robot_pb2

        from services.common.grpc_util import rpc_errors
        from services.kinematics.analytic import solve_nearest

        q = solve_nearest(self.spec, T_base_gripper, await self._joints())  # IKFailureError when unreachable
        with rpc_errors():
            reply = await self._robot().MoveJoints(
                robot_pb2.MoveJointsRequest(positions=[float(v) for v in q], speed_ratio=self.speed_ratio),
                timeout=self.settings.robot.motion_timeout_s,
            )
        if not reply.success:
            raise ExecutionError(f"move to a calibration pose failed: {reply.message}")
        await asyncio.sleep(self.settle_s)

    async def get_pose(self) -> np.ndarray:
        from services.kinematics.analytic import fk

        return fk(self.spec, await self._joints())


def _guess(
    settings: Settings, xyz: tuple[float, float, float] | None, rpy: tuple[float, float, float] | None
) -> np.ndarray:
    from services.common.camera_pose import load_T_base_camera, manual_T_base_camera

    if xyz is not None and rpy is not None:
        return manual_T_base_camera(xyz, rpy_deg=rpy)
    T, _ = load_T_base_camera(settings.vision.calibration)
    if T is None:
        raise ConfigurationError(
            "no camera pose to aim the board at: give --guess-xyz and --guess-rpy "
            "(a rough measurement is enough) or set vision.calibration.manual_*"
        )
    return T


@contextlib.asynccontextmanager
async def _live_calibration_cell(
    settings: Settings, source: str, seed: int
) -> AsyncIterator[tuple[Camera, Settings]]:
    """The configured camera; the robot is the running robot-driver service."""
    with open_camera(settings, source, seed) as cam:
        yield cam, settings


@contextlib.asynccontextmanager
async def _twin_calibration_cell(settings: Settings) -> AsyncIterator[tuple[Camera, Settings]]:
    """In-process twin cell on free loopback ports: the twin (board on the gripper) behind the simulated
    Dobot, the robot-driver service on it, and the twin's camera. Yields the camera and the settings
    that point the gRPC robot adapter at that driver."""
    from services.robot.service import RobotService
    from services.sim.app import build_sim_server
    from services.sim.twin.camera import TwinCamera
    from services.sim.twin.engine import TwinEngine

    server = build_sim_server(
        settings,
        "twin",
        q0_deg=settings.sim.twin.initial_joints_deg,
        ports={"dashboard": 0, "feedback": 0, "slow": 0},
    )
    async with server:
        robot = settings.robot.model_copy(
            update={
                "host": "127.0.0.1",
                "dashboard_port": server.ports["dashboard"],
                "feedback_port": server.ports["feedback"],
            }
        )
        s = settings.model_copy(update={"robot": robot})
        engine = server.controller.engine
        if not isinstance(engine, TwinEngine):  # build_sim_server(…, "twin") builds one
            raise ConfigurationError(
                f"the twin calibration cell needs the twin engine, got {type(engine).__name__}"
            )
        camera = TwinCamera(engine, seed=settings.sim.seed)
        try:
            async with RobotService(s, bus=None, grpc_port=0) as svc:
                await svc.driver.enable()
                grpc = s.grpc.model_copy(
                    update={"host": "127.0.0.1", "robot_port": svc.grpc_port, "robot_host": None}
                )
                yield camera, s.model_copy(update={"grpc": grpc})
        finally:
            camera.close()


@app.command("calibrate")
def calibrate(
    poses: Annotated[
        int | None, typer.Option(min=3, max=200, help="number of poses (default: settings)")
    ] = None,
    out: Annotated[
        Path | None, typer.Option(help="calibration file (default: vision.calibration.file)")
    ] = None,
    guess_xyz: Annotated[
        tuple[float, float, float] | None, typer.Option(help="rough camera position (m)")
    ] = None,
    guess_rpy: Annotated[
        tuple[float, float, float] | None, typer.Option(help="rough camera rpy (deg)")
    ] = None,
    speed: Annotated[int, typer.Option(min=1, max=100, help="speed ratio of the calibration moves (%)")] = 20,
    source: SourceOpt = "",
    seed: Annotated[int, typer.Option(min=0, help="pose generator seed")] = 0,
    profile: ProfileOpt = None,
) -> None:
    """Eye-to-hand calibration with the ChArUco board held by the gripper; writes the calibration file."""
    from services.vision.calibrate_workflow import run_calibration

    s = _settings(profile)
    in_twin = (source or s.vision.camera.source) == "twin"
    if in_twin:
        from services.sim.twin.calibration_board import twin_calibration_settings

        s = twin_calibration_settings(s)
    cal = s.vision.calibration.model_copy(update={"n_poses": poses}) if poses else s.vision.calibration
    path = _calibration_path(s, out)

    async def main() -> None:
        T_guess = _guess(s, guess_xyz, guess_rpy)
        cell = _twin_calibration_cell(s) if in_twin else _live_calibration_cell(s, source, seed)
        async with cell as (cam, robot_settings):
            with Progress(console=console) as bar:
                task = bar.add_task("calibrating", total=cal.n_poses)

                def progress(done: int, total: int, message: str) -> None:
                    bar.update(task, completed=done, description=message[:60])

                async with GrpcCalibrationRobot(robot_settings, speed) as robot:
                    result, data = await run_calibration(robot, cam, cal, T_guess, path, progress, seed)
        for why in data.skipped:
            console.print(f"  [yellow]{why}[/yellow]")
        t = result.T_base_camera[:3, 3]
        console.print(
            f"T_base_camera from {result.n_poses} views ({result.method}): position "
            f"({t[0]:.4f}, {t[1]:.4f}, {t[2]:.4f}) m; board consistency "
            f"{result.translation_rms_m * 1e3:.2f} mm / {result.rotation_rms_deg:.2f}° rms; "
            f"reprojection {result.reprojection_rms_px:.2f} px"
        )
        console.print(f"written to {path}")

    try:
        asyncio.run(main())
    except RobotError as exc:
        raise _fail(exc) from None


@app.command("calibrate-manual")
def calibrate_manual(
    xyz: Annotated[tuple[float, float, float], typer.Option(help="camera position in the base frame (m)")],
    rpy: Annotated[
        tuple[float, float, float], typer.Option(help="camera optical-frame rpy, fixed XYZ (deg)")
    ],
    out: Annotated[
        Path | None, typer.Option(help="calibration file (default: vision.calibration.file)")
    ] = None,
    profile: ProfileOpt = None,
) -> None:
    """Write a measured camera pose as the calibration (seed 001's PoC path)."""
    from services.common.camera_pose import manual_T_base_camera
    from services.vision.calibration import calibration_record, write_calibration

    s = _settings(profile)
    try:
        T = manual_T_base_camera(xyz, rpy_deg=rpy)
    except RobotError as exc:
        raise _fail(exc) from None
    path = write_calibration(
        _calibration_path(s, out), calibration_record(T, method="manual", notes="measured by hand")
    )
    console.print(f"manual calibration written to {path}")


@app.command("calibration-check")
def calibration_check(
    poses: Annotated[int, typer.Option(min=3, max=50)] = 4,
    speed: Annotated[int, typer.Option(min=1, max=100)] = 20,
    source: SourceOpt = "",
    seed: Annotated[int, typer.Option(min=0)] = 1,
    profile: ProfileOpt = None,
) -> None:
    """Quick drift check: where the board is seen vs where the robot says it holds it. Exit 1 on drift."""
    from services.common.camera_pose import read_calibration
    from services.common.charuco import CharucoTarget
    from services.vision.calibrate_workflow import check_calibration, generate_calibration_poses

    s = _settings(profile)
    cal = s.vision.calibration

    async def main() -> bool:
        saved = read_calibration(_calibration_path(s, None))
        if "T_gripper_board" not in saved.record:
            raise ConfigurationError(
                "the calibration file has no board mount (a manual calibration): "
                "run `pickplace calibrate` first"
            )
        Y = np.asarray(saved.record["T_gripper_board"], dtype=float)
        target = CharucoTarget(cal.board)
        with open_camera(s, source, seed) as cam:
            pose_list = generate_calibration_poses(
                poses,
                cal,
                saved.T_base_camera,
                Y,
                target.outline,
                np.random.default_rng(seed),
                cam.intrinsics,
            )
            async with GrpcCalibrationRobot(s, speed) as robot:
                report = await check_calibration(robot, cam, cal, saved.T_base_camera, Y, pose_list)
        console.print(("[green]" if report.ok else "[red]") + report.message)
        return report.ok

    try:
        ok = asyncio.run(main())
    except RobotError as exc:
        raise _fail(exc) from None
    if not ok:
        raise typer.Exit(1)
