"""A simulated UR controller in a child process, with a pipe to steer it (tests, benches, ``up``).

ur_rtde's interface constructors hold Python's GIL while they wait on the controller (pybind11
``py::init`` without a GIL release; RTDEControlInterface polls up to 5 s for its script to run), so
a controller simulated in the same interpreter would stand still exactly while a client waits for
it. The simulator therefore runs in its own process; the pipe carries what no UR protocol can (the
red e-stop button, pulling the cable) and snapshots of its state.
"""

from __future__ import annotations

import asyncio
import enum
import multiprocessing
import multiprocessing.connection
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from services.sim.ur.controller import URControllerConfig

START_TIMEOUT_S = 30.0  # a spawned interpreter imports numpy, scipy and the kinematics first
REQUEST_TIMEOUT_S = 10.0


class SimRequest(enum.Enum):
    SNAPSHOT = "snapshot"
    ESTOP = "estop"  # arg: pressed (bool)
    CUT_LINKS = "cut links"  # arg: outage (s of wall time) before connections are accepted again
    EVENTS = "events"
    STOP = "stop"


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
    seed: int | None = None  # the twin's scene


def _child(spec: SimSpec, conn: multiprocessing.connection.Connection) -> None:
    asyncio.run(_serve(spec, conn))


async def _serve(spec: SimSpec, conn: multiprocessing.connection.Connection) -> None:
    from services.kinematics.robot_models import get_robot
    from services.sim.ur.controller import URController
    from services.sim.ur.server import URPorts, URSimServer

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    engine = None
    config = spec.config or URControllerConfig()
    if spec.twin:
        from services.common.settings import load_settings
        from services.sim.twin.ur_cell import create_ur_twin_engine

        settings = load_settings("sim")
        engine = create_ur_twin_engine(settings, spec.model, spec.seed)
        if spec.config is None:  # start where the twin's arm stands
            config = URControllerConfig(
                q0=tuple(float(v) for v in np.deg2rad(settings.sim.twin.initial_joints_deg))
            )
    controller = URController(get_robot(spec.model), config, engine)
    ports = URPorts(spec.rtde_port, spec.dashboard_port, spec.script_ports)
    try:
        server = URSimServer(controller, spec.host, ports, spec.speed)
        await server.__aenter__()
    except BaseException as exc:
        conn.send(("error", repr(exc)))
        return

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
        stop.set()
        return None

    def reader() -> None:
        while True:
            try:
                kind, arg = conn.recv()
            except (EOFError, OSError):
                loop.call_soon_threadsafe(stop.set)
                return
            fut = asyncio.run_coroutine_threadsafe(handle(kind, arg), loop)
            try:
                conn.send(("ok", fut.result(REQUEST_TIMEOUT_S)))
            except Exception as exc:  # the answer to the request, never a crash of the sim
                conn.send(("error", repr(exc)))
            if kind is SimRequest.STOP:
                return

    threading.Thread(target=reader, name="sim-ur-pipe", daemon=True).start()
    conn.send(("ok", "ready"))
    try:
        await stop.wait()
    finally:
        await server.close()


class URSimProcess:
    """Context manager: the simulated controller listening on enter, stopped on exit."""

    def __init__(self, spec: SimSpec):
        self.spec = spec
        ctx = multiprocessing.get_context("spawn")
        self._conn, child_conn = ctx.Pipe()
        self._proc = ctx.Process(
            target=_child, args=(spec, child_conn), name=f"sim-ur-{spec.host}", daemon=True
        )
        self._lock = threading.Lock()

    @property
    def host(self) -> str:
        return self.spec.host

    def __enter__(self) -> URSimProcess:
        self._proc.start()
        if not self._conn.poll(START_TIMEOUT_S):
            self._proc.kill()
            raise TimeoutError(f"simulated UR controller on {self.spec.host} did not start")
        status, value = self._conn.recv()
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

    def request(self, kind: SimRequest, arg: Any = None) -> Any:
        with self._lock:
            self._conn.send((kind, arg))
            if not self._conn.poll(REQUEST_TIMEOUT_S):
                raise TimeoutError(f"simulated UR controller did not answer {kind.value}")
            status, value = self._conn.recv()
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
