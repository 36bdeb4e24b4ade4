"""The simulated cell on Zenoh when it runs as its own process (``pickplace sim-dobot``).

In one process (``pickplace up``) the vision service reads the twin's camera directly and
the cell resets the scene between cycles itself. When every service is its own OS process
(``pickplace up --processes``, docker compose, Kubernetes) the twin lives only in the
sim-dobot process, so that process

- publishes the simulated RealSense frames on ``CellKeys.camera_frames`` (the vision
  service's ``vision.camera.source: bus`` consumes them), and
- answers a Zenoh query on :attr:`CellKeys.sim_scene_reset`: lay out a fresh seeded scene (the
  simulated operator lays the rod down again) with the arm where it is, then reply with
  the new seed — so a caller knows frames published after the reply show the new scene.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import threading
import time
from typing import TYPE_CHECKING, Any

from services.common.bus import Bus
from services.common.cycle_watch import CycleWatch, follow_cycles
from services.common.errors import InvalidInputError, RobotCommunicationError
from services.common.keys import CellKeys
from services.common.live_config import with_twin
from services.common.sensors import CameraIntrinsics, RGBDFrame
from services.common.settings import Settings
from services.common.shell import ServiceShell, ShellStateError
from services.sim.dobot_server import SimDobotServer
from services.sim.scene_reset import SceneReset

if TYPE_CHECKING:
    from services.sim.twin.engine import TwinEngine

log = logging.getLogger("pickplace.sim.bus")

RESET_TIMEOUT_S = 30.0


class CurrentCamera:
    """A camera whose scene can be swapped: captures come from the twin's current camera."""

    def __init__(self, camera: Any):
        self._camera = camera
        self._lock = threading.Lock()

    def swap(self, camera: Any) -> Any:
        with self._lock:
            old, self._camera = self._camera, camera
        return old

    @property
    def intrinsics(self) -> CameraIntrinsics:
        with self._lock:
            return self._camera.intrinsics

    def capture(self) -> RGBDFrame:
        with self._lock:
            cam = self._camera
            return cam.capture()  # under the lock: a swap waits for the frame in flight

    def close(self) -> None:
        with self._lock:
            self._camera.close()


def parse_seed(payload: bytes, current: int) -> int:
    """The seed a reset query asks for: ``{"seed": n}``, or the next one when empty."""
    if not payload:
        return current + 1
    try:
        seed = json.loads(payload.decode())["seed"]
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise InvalidInputError(
            f'scene reset payload must be JSON {{"seed": int}}, got {payload[:60]!r}'
        ) from exc
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise InvalidInputError(f"scene reset seed must be a non-negative integer, got {seed!r}")
    return seed


class SimBusLink(ServiceShell):
    """Camera frames out, scene resets in, for one running :class:`SimDobotServer` with the twin engine."""

    kind = "sim-bus"

    def __init__(
        self,
        settings: Settings,
        server: SimDobotServer,
        bus: Bus,
        frames: bool = True,
        frame_rate: float | None = None,
    ):
        super().__init__()
        self.settings = settings
        self.frame_rate = frame_rate or settings.vision.rate_hz
        self.server = server
        self.bus = bus
        self.frames = frames
        self.seed = settings.sim.seed
        self.camera: CurrentCamera | None = None
        self.resets = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._reset = SceneReset(server, settings)
        self.cycle = CycleWatch()  # periodic frames pause while the task runs a cycle
        self.paused_periods = 0

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        from services.common.sensors import publish_camera_frames
        from services.sim.twin.camera import TwinCamera
        from services.sim.twin.engine import TwinEngine

        self._loop = asyncio.get_running_loop()
        keys = CellKeys(self.settings.cell_id)
        if self.frames:
            engine = self.server.controller.engine
            if not isinstance(engine, TwinEngine):
                raise InvalidInputError(
                    f"camera frames need the twin engine, this sim runs {type(engine).__name__}"
                )
            cam = await asyncio.to_thread(TwinCamera.ready, engine, self.seed)
            self.camera = CurrentCamera(cam)
            stack.push_async_callback(asyncio.to_thread, self.camera.close)
            # a detection the task waits for asks for its frame: rendered at once, not at the next
            # period (the twin renders at vision.rate_hz to spare the CPU; a real camera streams at
            # 15-30 fps, so without this a twin's DETECT waited up to a period a real cell does not)
            wanted = asyncio.Event()
            loop = self._loop

            def on_request(_key: str, _payload: bytes) -> None:  # a Zenoh thread
                loop.call_soon_threadsafe(wanted.set)

            requests = self.bus.subscribe_callback(keys.camera_frame_requests, on_request)
            stack.callback(self._undeclare, requests)
            # while a cycle runs only its own detections take frames (vision's live loop pauses too)
            follow_cycles(self.bus, self.settings.cell_id, self.cycle, stack)
            # runs until the shell cancels it (the stop event is for callers that stop it themselves)
            self.spawn(
                publish_camera_frames(
                    self.camera,
                    self.bus,
                    keys.camera_frames,
                    self.frame_rate,
                    asyncio.Event(),
                    wanted,
                    self._frames_paused,
                ),
                "frames",
            )
        queryable = self.bus.session.declare_queryable(keys.sim_scene_reset, self._on_query)
        stack.callback(self._undeclare, queryable)
        self.follow_config(self.bus, self.settings, self._on_config)
        log.info(
            "sim on zenoh: frames %s on %s, scene reset on %s",
            "published" if self.frames else "off",
            keys.camera_frames,
            keys.sim_scene_reset,
        )

    def _frames_paused(self) -> bool:
        paused = self.cycle.gives_way(time.monotonic(), self.settings.vision.live_during_cycle)
        self.paused_periods += paused
        return paused

    @staticmethod
    def _undeclare(queryable: Any) -> None:
        with contextlib.suppress(Exception):  # the session may be closing already
            queryable.undeclare()

    async def _on_config(self, new: Settings, changed: list[str]) -> None:
        """PUT /config: a changed scene layout is laid out at the next scene reset."""
        self.settings = with_twin(self.settings, new)

    # ------------------------------------------------------------------ scene reset
    def _on_query(self, query: Any) -> None:
        """Zenoh thread: hand the query to the event loop (the query is answered from there)."""
        payload = query.payload.to_bytes() if query.payload is not None else b""
        loop = self._loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop has closed: the query times out
                loop.call_soon_threadsafe(self._start_answer, query, payload)

    def _start_answer(self, query: Any, payload: bytes) -> None:
        try:
            self.spawn(self._answer(query, payload), "reset")
        except ShellStateError as exc:  # stopping: the caller hears why at once
            query.reply_err(json.dumps({"error": str(exc)}).encode())
            query.drop()

    async def _answer(self, query: Any, payload: bytes) -> None:
        try:
            seed = await self.reset_scene(parse_seed(payload, self.seed))
            query.reply(query.key_expr, json.dumps({"seed": seed}).encode())
        except Exception as exc:  # the caller gets the reason, the sim keeps running
            log.warning("scene reset failed: %s", exc)
            query.reply_err(json.dumps({"error": f"{type(exc).__name__}: {exc}"}).encode())
        finally:
            query.drop()

    async def reset_scene(self, seed: int) -> int:
        """A fresh seeded scene with the arm where it is now and the gripper outputs kept."""
        from services.sim.twin.camera import TwinCamera

        async def swap_camera(engine: TwinEngine) -> None:
            if self.camera is not None:
                cam = await asyncio.to_thread(TwinCamera.ready, engine, seed)
                old_cam = self.camera.swap(cam)
                await asyncio.to_thread(old_cam.close)

        await self._reset(seed, swap_camera)
        self.seed = seed
        self.resets += 1
        log.info("new twin scene, seed %d", seed)
        return seed


async def request_scene_reset(
    bus: Bus, cell_id: str, seed: int | None = None, timeout_s: float = RESET_TIMEOUT_S
) -> int:
    """Ask the sim-dobot process for a fresh scene; returns its seed once the new scene is live."""
    payload = b"" if seed is None else json.dumps({"seed": seed}).encode()
    key = CellKeys(cell_id).sim_scene_reset

    def ask() -> int:
        replies = bus.session.get(key, payload=payload, timeout=timeout_s)
        for reply in replies:
            if reply.ok is not None:
                return int(json.loads(reply.ok.payload.to_bytes().decode())["seed"])
            reason = reply.err.payload.to_bytes().decode() if reply.err is not None else "no reason given"
            raise RobotCommunicationError(f"scene reset on {key} refused: {reason}")
        raise RobotCommunicationError(
            f"no simulated cell answered a scene reset on {key} within {timeout_s} s"
        )

    return await asyncio.to_thread(ask)
