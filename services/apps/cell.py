"""The whole cell in one process (``pickplace up``, end-to-end tests, ``pickplace eval``).

Every service runs as it would alone — its own gRPC server on loopback, Zenoh on
loopback, the robot driver talking Dobot TCP to the simulated controller — so a
cycle crosses the same transports as in the multi-process deployment. Ports given
as 0 are chosen free and written back into the settings the task's clients use.

A UR model (``robot.model: ur5e | ur3``) runs the same cell on a simulated UR e-Series instead: the
controller in its own process (:mod:`services.sim.ur.process`) with the MuJoCo twin of the UR cell
behind it, its own loopback address, the driver over ur_rtde; the twin's camera frames, the scene
reset between cycles and the ground truth cross that process's pipe.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from services.common.bus import Bus
from services.common.live_config import LiveConfig, with_twin
from services.common.settings import Settings
from services.robot.service import RobotService
from services.sim.app import build_sim_server
from services.sim.dobot_server import SimDobotServer
from services.sim.scene_reset import SceneReset
from services.task.service import TaskService
from services.vision.service import VisionService

if TYPE_CHECKING:
    from services.sim.twin.ground_truth import CubePlaceResult, RodStandResult
    from services.sim.ur.process import URSimProcess
    from services.sim.ur.truth import SceneRecord

log = logging.getLogger("pickplace.cell")

UR_MODELS = ("ur5e", "ur3")
UR_SPEED_MAX = 100.0  # the simulated UR paces its clock; "as fast as possible" is this at most


class TwinTruth(Protocol):
    """The ground truth of the cell's twin an evaluation asks for (in process for the Nova5, across
    the simulated UR's pipe for a UR)."""

    def rod_standing(self) -> RodStandResult: ...
    def cube_in_zone(self, color: str) -> CubePlaceResult: ...
    def object_velocity(self, name: str) -> tuple[float, float]: ...
    def object_tilt_deg(self, name: str) -> float: ...
    def scene_record(self) -> SceneRecord: ...


def is_ur(settings: Settings) -> bool:
    return settings.robot.model in UR_MODELS


def with_updates(settings: Settings, **sections: dict[str, Any]) -> Settings:
    """A copy of the settings with some fields of some sections replaced (validated types kept)."""
    update = {name: getattr(settings, name).model_copy(update=values) for name, values in sections.items()}
    return settings.model_copy(update=update)


class Cell:
    def __init__(
        self,
        settings: Settings,
        engine: str = "twin",
        seed: int | None = None,
        perfect_calibration: bool = False,
        calibration_error: tuple[float, float] | None = None,
        live_vision: bool = True,
    ):
        self.settings = settings
        self.engine_name = engine
        self.seed = settings.sim.seed if seed is None else seed
        self.perfect_calibration = perfect_calibration
        self.calibration_error = calibration_error  # (metres, degrees) injected into T_base_camera
        self.live_vision = live_vision  # vision's live loop (the dashboard's frames between cycles)
        self.sim: SimDobotServer | None = None  # the simulated Nova5 ...
        self.ur_sim: URSimProcess | None = None  # ... or the simulated UR (robot.model ur5e | ur3)
        self.truth: TwinTruth | None = None  # the twin's ground truth (twin engine only)
        self.bus: Bus | None = None
        self.robot: RobotService | None = None
        self.vision: VisionService | None = None
        self.task: TaskService | None = None
        self._scene_reset: SceneReset | None = None
        self._stack = contextlib.AsyncExitStack()

    # ------------------------------------------------------------------ lifecycle
    async def __aenter__(self) -> Cell:
        try:
            await self._start()
        except BaseException:
            await self._stack.aclose()
            raise
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self._stack.aclose()

    async def _start(self) -> None:
        from services.grasp.service import GraspService
        from services.motion.service import MotionService

        s = with_updates(self.settings, sim={"seed": self.seed, "engine": self.engine_name})
        s = await self._start_ur_sim(s) if is_ur(s) else await self._start_dobot_sim(s)
        self.bus = Bus(s.zenoh)
        await self._stack.enter_async_context(self.bus)
        self.robot = RobotService(s, self.bus)
        await self._stack.enter_async_context(self.robot)
        await self.robot.driver.enable()
        motion = await self._stack.enter_async_context(MotionService(s, self.bus, s.grpc.motion_port))
        grasp = await self._stack.enter_async_context(GraspService(s, s.grpc.grasp_port))
        motion_port, grasp_port = motion.grpc_port, grasp.grpc_port
        await self._stack.enter_async_context(LiveConfig(self.bus, s, self._on_config))
        camera = await self._camera()
        self._stack.push_async_callback(self._close_camera)  # after the vision service has stopped
        self.vision = VisionService(
            s, self.bus, camera=camera, T_base_camera=self._calibration(s), publish_loop=self.live_vision
        )
        await self._stack.enter_async_context(self.vision)
        s = with_updates(
            s,
            grpc={
                "robot_port": self.robot.grpc_port,
                "motion_port": motion_port,
                "grasp_port": grasp_port,
                "vision_port": self.vision.grpc_port,
            },
        )
        self.task = TaskService(s, self.bus, clock=self.controller_clock)
        await self._stack.enter_async_context(self.task)
        s = with_updates(s, grpc={"task_port": self.task.grpc_port})
        self.task.runner.between_cycles = self.next_scene if s.task.reset_scene_each_cycle else None
        self.settings = s
        log.info(
            "cell up: sim %s, grpc robot %d motion %d grasp %d vision %d task %d",
            self.sim_address,
            self.robot.grpc_port,
            motion_port,
            grasp_port,
            self.vision.grpc_port,
            self.task.grpc_port,
        )

    async def _start_dobot_sim(self, s: Settings) -> Settings:
        self.sim = build_sim_server(s, self.engine_name)
        await self._stack.enter_async_context(self.sim)
        if self.engine_name == "twin":
            from services.sim.twin.ur_cell import EngineTruth

            self.truth = EngineTruth(lambda: self.engine)
        return with_updates(
            s,
            robot={
                "dashboard_port": self.sim.ports["dashboard"],
                "feedback_port": self.sim.ports["feedback"],
            },
        )

    async def _start_ur_sim(self, s: Settings) -> Settings:
        """The simulated UR with the twin of the UR cell, in its own process on a loopback address of
        its own (ur_rtde fixes the ports); the cell's settings become a UR cell's (driver ur_rtde,
        gripper on the tool outputs)."""
        from services.common.errors import ConfigurationError
        from services.sim.twin.ur_cell import ur_cell_settings
        from services.sim.ur.process import PipeTruth, SimSpec, URSimProcess
        from services.sim.ur.server import free_loopback_host

        if self.engine_name != "twin":
            raise ConfigurationError(
                f"a {s.robot.model} cell runs on the twin engine (its camera and objects), not {self.engine_name!r}"
            )
        s = ur_cell_settings(s, s.robot.model)
        host = await asyncio.to_thread(free_loopback_host)
        spec = SimSpec(
            s.robot.model,
            host,
            speed=min(s.sim.speed, UR_SPEED_MAX),
            twin=True,
            seed=self.seed,
            settings=s,
        )
        sim = URSimProcess(spec)
        await asyncio.to_thread(sim.__enter__)
        self._stack.push_async_callback(asyncio.to_thread, sim.__exit__, None, None, None)
        self.ur_sim, self.truth = sim, PipeTruth(sim)
        return with_updates(s, robot={"host": host})

    @property
    def sim_address(self) -> str:
        """Where the simulated controller listens (for the console)."""
        if self.ur_sim is not None:
            return f"{self.ur_sim.host} (RTDE 30004, dashboard 29999)"
        assert self.sim is not None
        return f"127.0.0.1:{self.sim.ports['dashboard']}"

    def sim_time(self) -> float:
        """The simulated controller's clock (s)."""
        if self.sim is not None:
            return float(self.sim.controller.sim_time)
        return self.controller_clock()

    @property
    def sim_late_ticks(self) -> int:
        """Control cycles the simulated Dobot ran late (the simulated UR slows its clock instead)."""
        return self.sim.late_ticks if self.sim is not None else 0

    async def _on_config(self, new: Settings, changed: list[str]) -> None:
        """PUT /config for the part of the cell this object holds: the twin's scene layout from the next
        scene (each service follows its own settings)."""
        if any(c.startswith("sim.twin.") for c in changed):
            self.settings = with_twin(self.settings, new)

    async def _close_camera(self) -> None:
        cam = self.vision.camera if self.vision is not None else None
        if cam is not None:
            await asyncio.to_thread(cam.close)

    def controller_clock(self) -> float:
        """The controller's clock (s): the newest feedback packet's TimeStamp, as the driver received it."""
        assert self.robot is not None
        fb = self.robot.driver.client.feedback
        assert fb is not None  # the driver has connected (and enabled) before the task starts
        return fb.timestamp_ms / 1000.0

    # ------------------------------------------------------------------ twin specifics
    @property
    def engine(self):  # type: ignore[no-untyped-def]
        assert self.sim is not None
        return self.sim.controller.engine

    async def _camera(self):  # type: ignore[no-untyped-def]
        if self.engine_name != "twin":
            return None
        if self.ur_sim is not None:
            from services.sim.ur.process import PipeCamera

            return PipeCamera(self.ur_sim)
        from services.sim.twin.camera import TwinCamera

        return await asyncio.to_thread(TwinCamera.ready, self.engine, self.seed)

    def _calibration(self, s: Settings) -> np.ndarray | None:
        """None = the vision service loads its calibration file (the default). The twin's true
        camera pose is used only when asked for (evaluation), optionally with an injected error."""
        if not self.perfect_calibration or self.engine_name != "twin":
            return None
        from scipy.spatial.transform import Rotation

        from services.sim.twin.ground_truth import T_base_camera

        T = T_base_camera(s.sim.twin.camera)
        if self.calibration_error:
            err_m, err_deg = self.calibration_error
            rng = np.random.default_rng(self.seed + 7919)
            d = rng.normal(size=3)
            ax = rng.normal(size=3)
            T = T.copy()
            T[:3, 3] += err_m * d / np.linalg.norm(d)
            T[:3, :3] = (
                Rotation.from_rotvec(np.deg2rad(err_deg) * ax / np.linalg.norm(ax)).as_matrix() @ T[:3, :3]
            )
        return T

    async def reset_scene(self, seed: int) -> None:
        """A fresh seeded scene (new rod pose, cube layout) with the arm where it is now."""
        from services.sim.twin.camera import TwinCamera
        from services.sim.twin.engine import TwinEngine

        if self.ur_sim is not None:  # the camera in the UR's process follows its engine there
            await asyncio.to_thread(self.ur_sim.reset_scene, seed)
            self.seed = seed
            return
        assert self.sim is not None and self.vision is not None
        vision = self.vision

        async def swap_camera(engine: TwinEngine) -> None:
            old_cam = vision.camera
            vision.camera = await asyncio.to_thread(TwinCamera.ready, engine, seed)
            if old_cam is not None:
                await asyncio.to_thread(old_cam.close)

        if self._scene_reset is None:
            self._scene_reset = SceneReset(self.sim, with_updates(self.settings, sim={"engine": "twin"}))
        await self._scene_reset(seed, swap_camera)
        self.seed = seed

    async def settle(self, sim_seconds: float) -> None:
        """Wait ``sim_seconds`` of the controller's (simulated) clock."""
        assert self.robot is not None
        await self.robot.driver.client.wait_controller_time(sim_seconds)

    async def next_scene(self) -> None:
        await self.reset_scene(self.seed + 1)
