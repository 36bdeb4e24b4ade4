"""The MuJoCo twin inside the simulated UR's process: its engine behind the controller, its camera, a
seeded scene reset between cycles and the ground truth an evaluation asks for. The process's pipe
(:mod:`services.sim.ur.process`) carries each of them to the cell; nothing here touches a socket.
"""

from __future__ import annotations

import asyncio
import logging

from services.common.sensors import CameraIntrinsics, RGBDFrame
from services.common.settings import Settings
from services.sim.twin.camera import TwinCamera
from services.sim.twin.engine import TwinEngine
from services.sim.twin.ur_cell import EngineTruth, create_ur_twin_engine
from services.sim.ur.controller import URController
from services.sim.ur.truth import TruthQuery

log = logging.getLogger("pickplace.sim.ur.twin")


class TwinHost:
    """Owns the twin engine (installed in ``controller``) and the camera that renders it."""

    def __init__(self, settings: Settings, model: str, seed: int):
        self.settings = settings
        self.model = model
        self.seed = seed
        self.engine: TwinEngine = create_ur_twin_engine(settings, model, seed)
        self.camera = TwinCamera.ready(self.engine, seed)
        self.truth = EngineTruth(lambda: self.engine)
        self._lock = asyncio.Lock()

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self.camera.intrinsics

    async def capture(self) -> RGBDFrame:
        """A frame of the scene as it is now (rendered on the camera's own GL thread)."""
        async with self._lock:  # never a camera a reset is closing
            return await asyncio.to_thread(self.camera.capture)

    async def reset_scene(self, controller: URController, seed: int) -> None:
        """A fresh seeded scene with the arm where it is now and the gripper outputs kept. The engine is
        swapped between two control cycles (the clock runs on this event loop), the camera after it."""
        async with self._lock:
            new = await asyncio.to_thread(create_ur_twin_engine, self.settings, self.model, seed)
            old, old_camera = self.engine, self.camera
            new.reset(controller.q)
            new.set_digital_outputs(controller.engine_digital_outputs)
            controller.engine = new
            self.engine, self.seed = new, seed
            self.camera = await asyncio.to_thread(TwinCamera.ready, new, seed)
        await asyncio.to_thread(old_camera.close)
        await asyncio.to_thread(old.close)
        log.info("UR twin: scene of seed %d", seed)

    def ask(self, query: TruthQuery, args: tuple[str, ...]) -> object:
        return self.truth.ask(query, *args)

    def close(self) -> None:
        self.camera.close()
        self.engine.close()
