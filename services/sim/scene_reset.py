"""A fresh seeded twin scene behind a running simulated controller: the one way both the in-process cell and
the sim-dobot process (``SimBusLink``) lay out a new scene between cycles."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING

from services.common.errors import InvalidInputError
from services.common.settings import Settings

if TYPE_CHECKING:
    from services.sim.dobot_server import SimDobotServer
    from services.sim.twin.engine import TwinEngine


class SceneReset:
    """Swaps the controller's twin engine for one built from ``seed``, with the arm where it is now and the
    gripper outputs kept. One reset at a time (the lock); the engine swap happens under the server's lock, so
    the clock thread never ticks a half-swapped controller."""

    def __init__(self, server: SimDobotServer, settings: Settings):
        self.server = server
        self.settings = settings
        self._lock = asyncio.Lock()

    async def __call__(self, seed: int, swap_camera: Callable[[TwinEngine], Awaitable[None]]) -> TwinEngine:
        """Build and install the new scene, let ``swap_camera`` point the caller's camera at it, then close the
        old engine; all under the one lock. Returns the new engine."""
        from services.sim.twin import create_twin_engine

        if self.settings.sim.engine != "twin":
            raise InvalidInputError(
                f"scene reset needs the twin engine, this sim runs {self.settings.sim.engine!r}"
            )
        async with self._lock:
            s = self.settings.model_copy(update={"sim": self.settings.sim.model_copy(update={"seed": seed})})
            new = await asyncio.to_thread(create_twin_engine, s, seed)
            with self.server.lock:
                ctrl = self.server.controller
                old = ctrl.engine
                new.reset(ctrl.measured.q)
                new.set_digital_outputs(ctrl.do_mask | (ctrl.tool_do_mask << 32))
                ctrl.engine = new
            await swap_camera(new)
            await asyncio.to_thread(old.close)
            return new
