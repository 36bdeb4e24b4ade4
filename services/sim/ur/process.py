"""A simulated UR controller in a child process, with a pipe to steer it (tests, benches, ``up``).

ur_rtde's interface constructors hold Python's GIL while they wait on the controller (pybind11
``py::init`` without a GIL release; RTDEControlInterface polls up to 5 s for its script to run), so
a controller simulated in the same interpreter would stand still exactly while a client waits for
it. The simulator therefore runs in its own process; the pipe carries what no UR protocol can (the
red e-stop button, pulling the cable) and snapshots of its state.

With the MuJoCo twin behind the controller (``SimSpec.twin``) the process also hosts the cell's camera
and ground truth (:class:`services.sim.ur.twin_host.TwinHost`): a second pipe carries the camera's
frames (so a render never holds up a control request), the first scene resets between cycles and the
ground truth an evaluation asks for.
"""

from __future__ import annotations

import asyncio
import enum
import itertools
import multiprocessing
import multiprocessing.connection
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from services.common.errors import CameraConnectionError
from services.common.sensors import CameraIntrinsics, RGBDFrame
from services.sim.ur.controller import URControllerConfig
from services.sim.ur.truth import SceneRecord, TruthQuery

if TYPE_CHECKING:
    from services.common.settings import Settings
    from services.sim.twin.ground_truth import CubePlaceResult, RodStandResult
    from services.sim.ur.twin_host import TwinHost

START_TIMEOUT_S = 30.0  # a spawned interpreter imports numpy, scipy and the kinematics first
REQUEST_TIMEOUT_S = 10.0
SCENE_TIMEOUT_S = 60.0  # a new twin scene: the MuJoCo model is compiled again


class SimRequest(enum.Enum):
    SNAPSHOT = "snapshot"
    ESTOP = "estop"  # arg: pressed (bool)
    CUT_LINKS = "cut links"  # arg: outage (s of wall time) before connections are accepted again
    EVENTS = "events"
    STOP = "stop"
    # the twin's (SimSpec.twin)
    CAPTURE = "capture"  # the camera's frame now (on the frame pipe)
    INTRINSICS = "intrinsics"  # the camera's (on the frame pipe)
    RESET_SCENE = "reset scene"  # arg: seed
    TRUTH = "truth"  # arg: (TruthQuery, args)


FRAME_REQUESTS = (SimRequest.CAPTURE, SimRequest.INTRINSICS)


@dataclass(frozen=True)
class SimSpec:
    model: str = "ur5e"
    host: str = "127.0.0.1"
    config: URControllerConfig | None = None
    speed: float = 1.0
    rtde_port: int = 30004
    dashboard_port: int = 29999
    script_ports: tuple[int, ...] = (30001, 30002, 30003)
    twin: bool = False  # the MuJoCo twin of the cell behind the controller (else the kinematic engine)
    seed: int | None = None  # the twin's scene (default settings.sim.seed)
    settings: Settings | None = None  # the cell the twin is built for (default: the sim profile's)


def _child(
    spec: SimSpec, conn: multiprocessing.connection.Connection, frames: multiprocessing.connection.Connection
) -> None:
    asyncio.run(_serve(spec, conn, frames))


async def _serve(
    spec: SimSpec, conn: multiprocessing.connection.Connection, frames: multiprocessing.connection.Connection
) -> None:
    from services.kinematics.robot_models import get_robot
    from services.sim.ur.controller import URController
    from services.sim.ur.server import URPorts, URSimServer

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    twin: TwinHost | None = None
    config = spec.config or URControllerConfig()
    try:
        if spec.twin:
            from services.common.settings import load_settings
            from services.sim.twin.ur_cell import ur_cell_settings
            from services.sim.ur.twin_host import TwinHost

            settings = ur_cell_settings(spec.settings or load_settings("sim"), spec.model)
            seed = settings.sim.seed if spec.seed is None else spec.seed
            twin = await asyncio.to_thread(TwinHost, settings, spec.model, seed)
            if spec.config is None:  # start where the twin's arm stands
                config = URControllerConfig(
                    q0=tuple(float(v) for v in np.deg2rad(settings.sim.twin.initial_joints_deg))
                )
        controller = URController(get_robot(spec.model), config, twin.engine if twin else None)
        ports = URPorts(spec.rtde_port, spec.dashboard_port, spec.script_ports)
        server = URSimServer(controller, spec.host, ports, spec.speed)
        await server.__aenter__()
    except BaseException as exc:
        if twin is not None:
            twin.close()
        conn.send((0, "error", repr(exc)))
        return

    def the_twin() -> TwinHost:
        if twin is None:
            raise CameraConnectionError("this simulated UR runs without the twin (SimSpec.twin)")
        return twin

    async def handle(kind: SimRequest, arg: Any) -> Any:
        if kind is SimRequest.SNAPSHOT:
            return server.snapshot()
        if kind is SimRequest.ESTOP:
            controller.press_estop(bool(arg))
            return None
        if kind is SimRequest.CUT_LINKS:
            await server.cut_links(float(arg or 0.0))
            return None
        if kind is SimRequest.EVENTS:
            return [e.text for e in controller.events]
        if kind is SimRequest.CAPTURE:
            return await the_twin().capture()
        if kind is SimRequest.INTRINSICS:
            return the_twin().intrinsics
        if kind is SimRequest.RESET_SCENE:
            await the_twin().reset_scene(controller, int(arg))
            return None
        if kind is SimRequest.TRUTH:
            query, args = arg
            return the_twin().ask(TruthQuery(query), tuple(args))
        stop.set()
        return None

    def reader(pipe: multiprocessing.connection.Connection) -> None:
        while True:
            try:
                seq, kind, arg = pipe.recv()
            except (EOFError, OSError):
                loop.call_soon_threadsafe(stop.set)
                return
            fut = asyncio.run_coroutine_threadsafe(handle(kind, arg), loop)
            try:
                pipe.send((seq, "ok", fut.result(SCENE_TIMEOUT_S)))
            except Exception as exc:  # the answer to the request, never a crash of the sim
                pipe.send((seq, "error", repr(exc)))
            if kind is SimRequest.STOP:
                return

    threading.Thread(target=reader, args=(conn,), name="sim-ur-pipe", daemon=True).start()
    threading.Thread(target=reader, args=(frames,), name="sim-ur-frames", daemon=True).start()
    conn.send((0, "ok", "ready"))
    try:
        await stop.wait()
    finally:
        await server.close()
        if twin is not None:
            await asyncio.to_thread(twin.close)


class URSimProcess:
    """Context manager: the simulated controller listening on enter, stopped on exit."""

    def __init__(self, spec: SimSpec):
        self.spec = spec
        ctx = multiprocessing.get_context("spawn")
        self._conn, child_conn = ctx.Pipe()
        self._frames, child_frames = ctx.Pipe()
        self._proc = ctx.Process(
            target=_child, args=(spec, child_conn, child_frames), name=f"sim-ur-{spec.host}", daemon=True
        )
        self._lock = threading.Lock()
        self._frames_lock = threading.Lock()
        self._seq = itertools.count(1)  # request numbers, shared by both pipes

    @property
    def host(self) -> str:
        return self.spec.host

    def __enter__(self) -> URSimProcess:
        self._proc.start()
        if not self._conn.poll(START_TIMEOUT_S + (SCENE_TIMEOUT_S if self.spec.twin else 0.0)):
            self._proc.kill()
            raise TimeoutError(f"simulated UR controller on {self.spec.host} did not start")
        _, status, value = self._conn.recv()
        if status != "ok":
            self._proc.join(5)
            raise RuntimeError(f"simulated UR controller on {self.spec.host} failed to start: {value}")
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            if self._proc.is_alive():
                self.request(SimRequest.STOP)
        except (OSError, EOFError, TimeoutError):
            pass
        self._proc.join(5)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(5)

    def request(self, kind: SimRequest, arg: Any = None, timeout_s: float = REQUEST_TIMEOUT_S) -> Any:
        conn, lock = (self._frames, self._frames_lock) if kind in FRAME_REQUESTS else (self._conn, self._lock)
        with lock:
            seq = next(self._seq)
            conn.send((seq, kind, arg))
            deadline = time.monotonic() + timeout_s
            while True:  # an answer to an earlier request that timed out is dropped, never taken for this one
                if not conn.poll(max(0.0, deadline - time.monotonic())):
                    raise TimeoutError(f"simulated UR controller did not answer {kind.value}")
                answered, status, value = conn.recv()
                if answered == seq:
                    break
        if status != "ok":
            raise RuntimeError(f"simulated UR controller failed {kind.value}: {value}")
        return value

    def snapshot(self) -> dict[str, Any]:
        result: dict[str, Any] = self.request(SimRequest.SNAPSHOT)
        return result

    def press_estop(self, pressed: bool = True) -> None:
        self.request(SimRequest.ESTOP, pressed)

    def cut_links(self, outage_s: float = 0.0) -> None:
        """Pull the cable for ``outage_s`` (returns once it is back)."""
        self.request(SimRequest.CUT_LINKS, outage_s)

    def events(self) -> list[str]:
        result: list[str] = self.request(SimRequest.EVENTS)
        return result

    # ------------------------------------------------------------------ the twin (SimSpec.twin)
    def capture(self) -> RGBDFrame:
        frame: RGBDFrame = self.request(SimRequest.CAPTURE)
        return frame

    def intrinsics(self) -> CameraIntrinsics:
        result: CameraIntrinsics = self.request(SimRequest.INTRINSICS)
        return result

    def reset_scene(self, seed: int) -> None:
        """A fresh twin scene of ``seed``, the arm where it is (returns once it is in place)."""
        self.request(SimRequest.RESET_SCENE, seed, SCENE_TIMEOUT_S)

    def truth(self, query: TruthQuery, *args: str) -> Any:
        return self.request(SimRequest.TRUTH, (query, args))


class PipeCamera:
    """The twin's camera in the simulated UR's process, as a :class:`services.common.sensors.Camera`."""

    def __init__(self, sim: URSimProcess):
        self._sim = sim
        self._intrinsics = sim.intrinsics()
        self._closed = False

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intrinsics

    def capture(self) -> RGBDFrame:
        if self._closed:
            raise CameraConnectionError("the UR twin's camera is closed")
        try:
            return self._sim.capture()
        except (OSError, EOFError, TimeoutError, RuntimeError) as exc:
            raise CameraConnectionError(f"the UR twin's camera: {exc}") from exc

    def close(self) -> None:
        self._closed = True


class PipeTruth:
    """The UR twin's ground truth across the pipe: :class:`services.sim.twin.ur_cell.EngineTruth`'s
    questions, answered in the simulated controller's process."""

    def __init__(self, sim: URSimProcess):
        self._sim = sim

    def rod_standing(self) -> RodStandResult:
        return self._sim.truth(TruthQuery.ROD_STANDING)

    def cube_in_zone(self, color: str) -> CubePlaceResult:
        return self._sim.truth(TruthQuery.CUBE_IN_ZONE, color)

    def object_velocity(self, name: str) -> tuple[float, float]:
        return self._sim.truth(TruthQuery.OBJECT_VELOCITY, name)

    def object_tilt_deg(self, name: str) -> float:
        return float(self._sim.truth(TruthQuery.OBJECT_TILT_DEG, name))

    def scene_record(self) -> SceneRecord:
        return self._sim.truth(TruthQuery.SCENE_RECORD)
