"""``pickplace up --processes``: the deployed topology as separate OS processes on loopback.

Each service runs as its own process with exactly the command docker compose runs
(``pickplace serve <service>``, ``pickplace sim-dobot``) and the same ``PICKPLACE_*``
environment variable names, pointed at loopback ports instead of container names.
This process is the Zenoh rendezvous (a router session listening on loopback; the
services join as Zenoh clients, as they join the ``zenoh`` container in compose), it
serves each child's Prometheus metrics (the child writes them to its own
``PROMETHEUS_MULTIPROC_DIR``), restarts a child that dies (and says so), and on
Ctrl-C stops every child: SIGTERM, then SIGKILL after a grace period.

Also here, for compose/Kubernetes probes and the lead's CLI: :func:`check_health`
(``python -m services.apps.launcher health <service>``), :func:`start_metrics_exporter`
(the in-container exporter behind ``PICKPLACE_METRICS__PORT``) and :func:`drive_cycles`
(enable the arm, run pick cycles through the task service, fresh twin scene between them).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import shutil
import signal
import sys
import time
import urllib.request
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import typer

from services.common.aio import run_until_signal
from services.common.errors import ConfigurationError, RobotCommunicationError
from services.common.net import free_loopback_ports
from services.common.settings import REPO_ROOT, Settings, load_settings

log = logging.getLogger("pickplace.launcher")

# Start order: the simulated controller first (the robot driver connects to it), the gateway last.
SERVICES = ("sim-dobot", "robot", "motion", "grasp", "vision", "task", "gateway")
GRPC_SERVICES = ("robot", "motion", "grasp", "vision", "task")
MULTIPROC_ENV = "PROMETHEUS_MULTIPROC_DIR"

# Environment names only containers need: binding every interface, reaching peers by service name.
CONTAINER_ONLY_ENV = frozenset(
    {
        "PICKPLACE_GRPC__HOST",
        "PICKPLACE_ZENOH__ALLOW_REMOTE",
        "PICKPLACE_GATEWAY__HOST",
        "PICKPLACE_GATEWAY__ALLOW_REMOTE",
        "PICKPLACE_METRICS__HOST",
        "PICKPLACE_METRICS__ALLOW_REMOTE",
        "PICKPLACE_METRICS__PORT",
        "MUJOCO_GL",
        *(f"PICKPLACE_GRPC__{s.upper()}_HOST" for s in GRPC_SERVICES),
    }
)
# Names only the local run sets: a per-process log file, a throw-away PostgreSQL schema (tests).
LOCAL_ONLY_ENV = frozenset({"PICKPLACE_LOGGING__FILE", "PICKPLACE_DATABASE__SCHEMA_NAME"})

DEFAULT_METRICS_PORTS = {
    "sim-dobot": 9100,
    "robot": 9101,
    "motion": 9102,
    "grasp": 9103,
    "vision": 9104,
    "task": 9105,
}
DEFAULT_ZENOH_PORT = 7447


# ---------------------------------------------------------------------------- topology (pure)
@dataclass(frozen=True)
class LocalPorts:
    """Every loopback port of the local topology."""

    zenoh: int
    grpc: dict[str, int]
    gateway: int
    edge: int
    sim_dashboard: int
    sim_feedback: int
    sim_slow: int
    metrics: dict[str, int]

    @classmethod
    def from_settings(cls, s: Settings) -> LocalPorts:
        zenoh_port = DEFAULT_ZENOH_PORT
        for ep in s.zenoh.listen:
            with contextlib.suppress(ValueError):
                zenoh_port = int(ep.rsplit(":", 1)[1])
                break
        return cls(
            zenoh=zenoh_port,
            grpc={name: getattr(s.grpc, f"{name}_port") for name in GRPC_SERVICES},
            gateway=s.gateway.port,
            edge=s.gateway.edge_grpc_port or 0,
            sim_dashboard=s.sim.dashboard_port,
            sim_feedback=s.sim.feedback_port,
            sim_slow=s.sim.slow_feedback_port,
            metrics=dict(DEFAULT_METRICS_PORTS),
        )

    @classmethod
    def free(cls) -> LocalPorts:
        """All ports chosen free on 127.0.0.1 (tests; two runs side by side)."""
        ports = free_loopback_ports(12 + len(DEFAULT_METRICS_PORTS))
        it = iter(ports)
        return cls(
            zenoh=next(it),
            grpc={name: next(it) for name in GRPC_SERVICES},
            gateway=next(it),
            edge=next(it),
            sim_dashboard=next(it),
            sim_feedback=next(it),
            sim_slow=next(it),
            metrics={name: next(it) for name in DEFAULT_METRICS_PORTS},
        )

    def all(self) -> dict[str, int]:
        out = {
            "zenoh": self.zenoh,
            "gateway": self.gateway,
            "gateway-edge": self.edge,
            "sim-dashboard": self.sim_dashboard,
            "sim-feedback": self.sim_feedback,
            "sim-slow": self.sim_slow,
        }
        out.update({f"grpc-{k}": v for k, v in self.grpc.items()})
        out.update({f"metrics-{k}": v for k, v in self.metrics.items()})
        return out

    def check(self) -> None:
        used = {k: v for k, v in self.all().items() if v}
        seen: dict[int, str] = {}
        for name, port in used.items():
            if port in seen:
                raise ConfigurationError(f"port {port} is given to both {seen[port]} and {name}")
            seen[port] = name


@dataclass(frozen=True)
class ProcessSpec:
    """One child: its name, its command line (after the ``pickplace`` program) and its environment."""

    name: str
    args: tuple[str, ...]
    env: dict[str, str]
    metrics_port: int | None = None


def pickplace_program() -> list[str]:
    """The ``pickplace`` console script of this interpreter's environment (else ``python -m services.apps.cli``)."""
    script = Path(sys.executable).with_name("pickplace")
    return [str(script)] if script.exists() else [sys.executable, "-m", "services.apps.cli"]


def service_args(name: str) -> tuple[str, ...]:
    """The command each service runs, the same in compose, Kubernetes and here."""
    if name == "sim-dobot":
        return ("sim-dobot", "--engine", "twin")
    if name not in SERVICES:
        raise ConfigurationError(f"unknown service {name!r}; the topology has {list(SERVICES)}")
    return ("serve", name)


def topology(
    settings: Settings,
    ports: LocalPorts,
    *,
    api_token: str,
    metrics_root: Path | None = None,
    log_dir: Path | None = None,
    database_url: str | None = None,
    seed: int | None = None,
    state_dir: Path | None = None,
) -> list[ProcessSpec]:
    """The child processes of the local run, in start order (pure: no I/O)."""
    ports.check()
    common = {
        "PICKPLACE_PROFILE": settings.profile,
        "PICKPLACE_CELL_ID": settings.cell_id,
        "PICKPLACE_ZENOH__MODE": "client",
        "PICKPLACE_ZENOH__LISTEN": "[]",
        "PICKPLACE_ZENOH__CONNECT": json.dumps([f"tcp/127.0.0.1:{ports.zenoh}"]),
        **{f"PICKPLACE_GRPC__{name.upper()}_PORT": str(port) for name, port in ports.grpc.items()},
    }
    specific: dict[str, dict[str, str]] = {
        "sim-dobot": {
            "PICKPLACE_SIM__ENGINE": "twin",
            "PICKPLACE_SIM__SEED": str(settings.sim.seed if seed is None else seed),
            "PICKPLACE_SIM__DASHBOARD_PORT": str(ports.sim_dashboard),
            "PICKPLACE_SIM__FEEDBACK_PORT": str(ports.sim_feedback),
            "PICKPLACE_SIM__SLOW_FEEDBACK_PORT": str(ports.sim_slow),
        },
        "robot": {
            "PICKPLACE_ROBOT__DASHBOARD_PORT": str(ports.sim_dashboard),
            "PICKPLACE_ROBOT__FEEDBACK_PORT": str(ports.sim_feedback),
        },
        "gateway": {
            "PICKPLACE_DATABASE__URL": database_url or settings.database.url,
            "PICKPLACE_GATEWAY__API_TOKEN": api_token,
            "PICKPLACE_GATEWAY__PORT": str(ports.gateway),
            "PICKPLACE_GATEWAY__EDGE_GRPC_PORT": str(ports.edge),
            # picks held while the database is down survive a gateway restart here
            "PICKPLACE_GATEWAY__PICK_SPILL_FILE": str(state_dir / "pick_spill.jsonl")
            if state_dir
            else str(settings.gateway.pick_spill_file),
        },
    }
    if settings.database.schema_name:
        specific["gateway"]["PICKPLACE_DATABASE__SCHEMA_NAME"] = settings.database.schema_name
    specs = []
    for name in SERVICES:
        env = {**common, **specific.get(name, {})}
        if log_dir is not None:
            env["PICKPLACE_LOGGING__FILE"] = str(log_dir / f"{name}.log")
        metrics_port = None
        # The gateway renders its own registry at /metrics; every other service writes to a directory.
        if name != "gateway" and metrics_root is not None:
            env[MULTIPROC_ENV] = str(metrics_root / name)
            metrics_port = ports.metrics[name]
        specs.append(ProcessSpec(name, service_args(name), env, metrics_port))
    return specs


# ---------------------------------------------------------------------------- health
def _dial_host(host: str) -> str:
    return "127.0.0.1" if host in ("0.0.0.0", "", "::") else host


async def check_health(settings: Settings, service: str, timeout_s: float = 3.0) -> str:
    """Is ``service`` up and answering? Returns what was checked; raises RobotCommunicationError if not."""
    if service == "sim-dobot":
        host, port = _dial_host(settings.sim.host), settings.sim.dashboard_port
        try:
            _r, w = await asyncio.wait_for(asyncio.open_connection(host, port), timeout_s)
        except (OSError, TimeoutError) as exc:
            raise RobotCommunicationError(
                f"simulated Dobot dashboard {host}:{port} not reachable: {exc}"
            ) from exc
        w.close()
        with contextlib.suppress(OSError):
            await w.wait_closed()
        return f"sim-dobot dashboard {host}:{port} accepts connections"
    if service in GRPC_SERVICES:
        import grpc

        host = _dial_host(settings.grpc.client_host(service))  # type: ignore[arg-type]
        port = getattr(settings.grpc, f"{service}_port")
        async with grpc.aio.insecure_channel(f"{host}:{port}") as ch:
            try:
                await asyncio.wait_for(ch.channel_ready(), timeout_s)
            except TimeoutError as exc:
                raise RobotCommunicationError(
                    f"{service} gRPC {host}:{port} not ready within {timeout_s} s"
                ) from exc
        return f"{service} gRPC {host}:{port} ready"
    if service == "gateway":
        url = f"http://{_dial_host(settings.gateway.host)}:{settings.gateway.port}/api/v1/system/status"

        def get() -> int:
            with urllib.request.urlopen(url, timeout=timeout_s) as r:
                return int(r.status)

        try:
            code = await asyncio.to_thread(get)
        except OSError as exc:
            raise RobotCommunicationError(f"gateway {url} not answering: {exc}") from exc
        if code != 200:
            raise RobotCommunicationError(f"gateway {url} answered HTTP {code}")
        return f"gateway {url} answers 200"
    raise ConfigurationError(f"unknown service {service!r}; known: {list(SERVICES)}")


# ---------------------------------------------------------------------------- metrics
def start_metrics_exporter(settings: Settings) -> Any:
    """Serve this process's metrics on ``metrics.host:metrics.port`` (None = off); returns the server.

    The services keep their metrics on private registries, so the exporter reads what the
    process wrote to ``PROMETHEUS_MULTIPROC_DIR`` (which must be set before prometheus_client
    is first imported — the container's environment does that).
    """
    if settings.metrics.port is None:
        return None
    path = os.environ.get(MULTIPROC_ENV)
    if not path:
        raise ConfigurationError(
            f"metrics.port {settings.metrics.port} needs {MULTIPROC_ENV} set to a directory"
        )
    Path(path).mkdir(parents=True, exist_ok=True)
    return serve_metrics_dir(Path(path), settings.metrics.host, settings.metrics.port)


def serve_metrics_dir(path: Path, host: str, port: int) -> Any:
    """An HTTP ``/metrics`` of every metric written under ``path`` (prometheus-client's multiprocess files)."""
    from prometheus_client import CollectorRegistry, start_http_server
    from prometheus_client.multiprocess import MultiProcessCollector

    path.mkdir(parents=True, exist_ok=True)
    registry = CollectorRegistry()
    MultiProcessCollector(registry, path=str(path))
    try:
        server, _thread = start_http_server(port, host, registry=registry)
    except OSError as exc:
        raise RobotCommunicationError(f"cannot serve metrics on {host}:{port}: {exc}") from exc
    return server


# ---------------------------------------------------------------------------- the process supervisor
@dataclass
class Child:
    spec: ProcessSpec
    proc: asyncio.subprocess.Process | None = None
    restarts: int = 0
    exits: list[int] = field(default_factory=list)
    started_at: float = 0.0

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None else None

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.returncode is None


@dataclass(frozen=True)
class LauncherEvent:
    service: str
    kind: str  # started | healthy | exited | restarting | gave-up
    detail: str
    at: float = field(default_factory=time.time)


class Launcher:
    """Start, watch, restart and stop the child processes; be the Zenoh rendezvous; serve their metrics."""

    def __init__(
        self,
        settings: Settings,
        specs: Sequence[ProcessSpec],
        ports: LocalPorts,
        *,
        log_dir: Path,
        metrics_root: Path | None = None,
        health_timeout_s: float = 180.0,
        restart_delay_s: float = 1.0,
        max_restarts: int = 10,
        stop_grace_s: float = 10.0,
        on_event: Callable[[LauncherEvent], None] | None = None,
    ):
        self.settings = child_view(settings, ports)
        self.specs = list(specs)
        self.ports = ports
        self.log_dir = log_dir
        self.metrics_root = metrics_root
        self.health_timeout_s = health_timeout_s
        self.restart_delay_s = restart_delay_s
        self.max_restarts = max_restarts
        self.stop_grace_s = stop_grace_s
        self.on_event = on_event
        self.children = {spec.name: Child(spec) for spec in self.specs}
        self.events: list[LauncherEvent] = []
        self._stopping = False
        self._watchers: list[asyncio.Task[None]] = []
        self._router: Any = None
        self._metrics_servers: list[Any] = []

    # ---------------------------------------------------------------- lifecycle
    async def __aenter__(self) -> Launcher:
        try:
            await self.start()
        except BaseException:
            await self.stop()
            raise
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def start(self) -> None:
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self._router = await asyncio.to_thread(self._open_router)
        if self.metrics_root is not None:
            for spec in self.specs:
                if spec.metrics_port is not None:
                    path = Path(spec.env[MULTIPROC_ENV])
                    shutil.rmtree(path, ignore_errors=True)  # a fresh run starts its counters at zero
                    self._metrics_servers.append(serve_metrics_dir(path, "127.0.0.1", spec.metrics_port))
        gateway = self.children.get("gateway")
        if gateway is not None:
            await self.run_once("db-upgrade", ("db", "upgrade"), gateway.spec.env)
        # The controller first, then its driver; the stateless planners and the rest together.
        for group in (("sim-dobot",), ("robot",), ("motion", "grasp", "vision", "task"), ("gateway",)):
            names = [n for n in group if n in self.children]
            for n in names:
                await self._spawn(self.children[n])
            await asyncio.gather(*(self.wait_healthy(n) for n in names))
        for child in self.children.values():
            self._watchers.append(
                asyncio.create_task(self._watch(child), name=f"launcher.watch.{child.spec.name}")
            )

    def _open_router(self) -> Any:
        from services.common.bus import open_session

        zs = self.settings.zenoh.model_copy(
            update={"mode": "router", "connect": [], "listen": [f"tcp/127.0.0.1:{self.ports.zenoh}"]}
        )
        return open_session(zs)

    async def stop(self) -> None:
        """SIGTERM every child (gateway first, the controller last), SIGKILL what is left after the grace."""
        self._stopping = True
        for t in self._watchers:
            t.cancel()
        await asyncio.gather(*self._watchers, return_exceptions=True)
        self._watchers.clear()
        for name in reversed(SERVICES):
            child = self.children.get(name)
            if child is not None and child.alive:
                assert child.proc is not None
                with contextlib.suppress(ProcessLookupError):
                    child.proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + self.stop_grace_s
        for child in self.children.values():
            if child.proc is None:
                continue
            try:
                await asyncio.wait_for(child.proc.wait(), max(0.1, deadline - time.monotonic()))
            except TimeoutError:
                log.warning("%s did not stop within %.0f s; killing it", child.spec.name, self.stop_grace_s)
                with contextlib.suppress(ProcessLookupError):
                    child.proc.kill()
                await child.proc.wait()
        for server in self._metrics_servers:
            with contextlib.suppress(Exception):
                server.shutdown()
                server.server_close()
        self._metrics_servers.clear()
        if self._router is not None:
            router, self._router = self._router, None
            with contextlib.suppress(Exception):
                await asyncio.to_thread(router.close)

    # ---------------------------------------------------------------- children
    def _event(self, service: str, kind: str, detail: str) -> None:
        ev = LauncherEvent(service, kind, detail)
        self.events.append(ev)
        level = logging.WARNING if kind in ("exited", "restarting", "gave-up") else logging.INFO
        log.log(level, "%s %s: %s", service, kind, detail)
        if self.on_event is not None:
            self.on_event(ev)

    def _child_env(self, spec_env: dict[str, str]) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("PICKPLACE_") and k != MULTIPROC_ENV}
        env.setdefault("MUJOCO_GL", "egl")
        env.update(spec_env)
        return env

    async def run_once(
        self, name: str, args: Sequence[str], env: dict[str, str], timeout_s: float = 120.0
    ) -> None:
        """A one-shot command (the database migration) with a service's environment; raise if it fails."""
        out = self.log_dir / f"{name}.log"
        with out.open("ab") as fh:
            proc = await asyncio.create_subprocess_exec(
                *pickplace_program(),
                *args,
                env=self._child_env(env),
                cwd=REPO_ROOT,
                stdin=asyncio.subprocess.DEVNULL,
                stdout=fh,
                stderr=asyncio.subprocess.STDOUT,
                start_new_session=True,
            )
            try:
                code = await asyncio.wait_for(proc.wait(), timeout_s)
            except TimeoutError:
                proc.kill()
                await proc.wait()
                raise ConfigurationError(
                    f"`pickplace {' '.join(args)}` did not finish in {timeout_s} s"
                ) from None
        if code != 0:
            tail = out.read_text(errors="replace").strip().splitlines()[-3:]
            raise ConfigurationError(
                f"`pickplace {' '.join(args)}` failed with exit code {code}: {' | '.join(tail)}"
            )

    async def _spawn(self, child: Child) -> None:
        spec = child.spec
        out = self.log_dir / f"{spec.name}.out"
        with out.open("ab") as fh:
            # Own session: a Ctrl-C in the terminal reaches the launcher only, which stops children in order.
            # No preexec_fn: Python code between fork and exec in this threaded process (gRPC, Zenoh)
            # crashed a child with SIGSEGV; the C fork/exec path runs none.
            child.proc = await asyncio.create_subprocess_exec(
                *pickplace_program(),
                *spec.args,
                env=self._child_env(spec.env),
                cwd=REPO_ROOT,
                stdin=asyncio.subprocess.DEVNULL,
                stdout=fh,
                stderr=asyncio.subprocess.STDOUT,
                start_new_session=True,
            )
        child.started_at = time.monotonic()
        self._event(spec.name, "started", f"pid {child.proc.pid}: pickplace {' '.join(spec.args)}")

    async def wait_healthy(self, name: str, timeout_s: float | None = None) -> None:
        child = self.children[name]
        deadline = time.monotonic() + (timeout_s or self.health_timeout_s)
        last = ""
        while time.monotonic() < deadline:
            if not child.alive:
                raise RobotCommunicationError(
                    f"{name} exited with code {child.proc.returncode if child.proc else None} while starting; "
                    f"see {self.log_dir / (name + '.out')}"
                )
            try:
                detail = await check_health(self.settings, name, timeout_s=2.0)
            except RobotCommunicationError as exc:
                last = str(exc)
                await asyncio.sleep(0.3)
                continue
            self._event(name, "healthy", detail)
            return
        raise RobotCommunicationError(
            f"{name} not healthy within {timeout_s or self.health_timeout_s} s: {last}"
        )

    async def _watch(self, child: Child) -> None:
        """Report a child that exits on its own and start it again (with a growing pause)."""
        name = child.spec.name
        while not self._stopping:
            assert child.proc is not None
            code = await child.proc.wait()
            if self._stopping:
                return
            child.exits.append(code)
            self._event(name, "exited", f"pid {child.proc.pid} exited with code {code}")
            if child.restarts >= self.max_restarts:
                self._event(name, "gave-up", f"restarted {child.restarts} times already")
                return
            child.restarts += 1
            delay = min(self.restart_delay_s * 2 ** (child.restarts - 1), 30.0)
            self._event(name, "restarting", f"restart {child.restarts} in {delay:.1f} s")
            await asyncio.sleep(delay)
            await self._spawn(child)
            try:
                await self.wait_healthy(name)
            except RobotCommunicationError as exc:
                log.warning("%s", exc)

    async def wait_restarted(self, name: str, restarts: int, timeout_s: float = 180.0) -> None:
        """Until ``name`` has been restarted ``restarts`` times and is healthy again."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            healthy_after = [e for e in self.events if e.service == name and e.kind == "healthy"]
            if self.children[name].restarts >= restarts and len(healthy_after) > restarts:
                return
            await asyncio.sleep(0.2)
        raise RobotCommunicationError(
            f"{name} was not restarted {restarts} time(s) and healthy within {timeout_s} s"
        )


def child_view(settings: Settings, ports: LocalPorts) -> Settings:
    """The settings as the children see them (their ports), for health checks and clients in this process."""
    grpc = settings.grpc.model_copy(update={f"{n}_port": p for n, p in ports.grpc.items()})
    sim = settings.sim.model_copy(
        update={
            "dashboard_port": ports.sim_dashboard,
            "feedback_port": ports.sim_feedback,
            "slow_feedback_port": ports.sim_slow,
        }
    )
    gw = settings.gateway.model_copy(update={"port": ports.gateway, "edge_grpc_port": ports.edge})
    zenoh = settings.zenoh.model_copy(
        update={"mode": "client", "listen": [], "connect": [f"tcp/127.0.0.1:{ports.zenoh}"]}
    )
    return settings.model_copy(update={"grpc": grpc, "sim": sim, "gateway": gw, "zenoh": zenoh})


# ---------------------------------------------------------------------------- driving the cell
async def enable_robot(settings: Settings) -> None:
    from pickplace.v1 import robot_pb2, robot_pb2_grpc

    from services.common.grpc_util import channel, rpc_errors

    async with channel(settings.grpc.client_host("robot"), settings.grpc.robot_port) as ch:
        with rpc_errors():
            await robot_pb2_grpc.RobotControllerStub(ch).Enable(robot_pb2.EnableRequest(), timeout=30.0)


async def park_arm(settings: Settings) -> None:
    """After a cycle that gave up: clear alarms, open the jaws and go to SAFE_HOME (out of the camera's view)."""
    import numpy as np
    from pickplace.v1 import robot_pb2, robot_pb2_grpc

    from services.common.grpc_util import channel, rpc_errors

    home = np.deg2rad(settings.grasp.safe_home_joints_deg[settings.robot.model]).tolist()
    async with channel(settings.grpc.client_host("robot"), settings.grpc.robot_port) as ch:
        stub = robot_pb2_grpc.RobotControllerStub(ch)
        with rpc_errors():
            await stub.ClearError(robot_pb2.ClearErrorRequest(), timeout=30.0)
            await stub.Enable(robot_pb2.EnableRequest(), timeout=30.0)
            await stub.SetGripper(robot_pb2.SetGripperRequest(close=False), timeout=30.0)
            await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=home), timeout=120.0)


async def run_single_cycle(settings: Settings, task: str = "", timeout_s: float = 300.0) -> Any:
    """One pick cycle through the task service's gRPC; returns its PickEvent."""
    from pickplace.v1 import task_pb2, task_pb2_grpc

    from services.common.grpc_util import channel, rpc_errors

    async with channel(settings.grpc.client_host("task"), settings.grpc.task_port) as ch:
        with rpc_errors():
            return await task_pb2_grpc.TaskControllerStub(ch).RunSingleCycle(
                task_pb2.SingleCycleRequest(task=task), timeout=timeout_s
            )


async def drive_cycles(
    settings: Settings,
    cycles: int = 0,
    on_pick: Callable[[Any], None] | None = None,
    pause_s: float | None = None,
) -> list[Any]:
    """Enable the arm, then run cycles (0 = until cancelled), with a fresh twin scene after each."""
    from services.common.bus import Bus
    from services.sim.bus_link import request_scene_reset

    await enable_robot(settings)
    picks: list[Any] = []
    pause = settings.task.pause_between_cycles_s if pause_s is None else pause_s
    zs = settings.zenoh.model_copy(update={"mode": "client", "listen": []})
    async with Bus(zs) as bus:
        n = 0
        while cycles == 0 or n < cycles:
            n += 1
            try:
                event = await run_single_cycle(settings, settings.task.task)
            except Exception as exc:  # a crashed service mid-cycle: say so, wait, go on
                log.warning("cycle %d did not complete: %s", n, exc)
                await asyncio.sleep(2.0)
                continue
            picks.append(event)
            if on_pick is not None:
                on_pick(event)
            if not event.success:
                try:
                    await park_arm(settings)
                except Exception as exc:
                    log.warning("could not park the arm after cycle %d: %s", n, exc)
            if settings.task.reset_scene_each_cycle and (cycles == 0 or n < cycles):
                try:
                    await request_scene_reset(bus, settings.cell_id)
                except Exception as exc:
                    log.warning("no fresh scene after cycle %d: %s", n, exc)
            await asyncio.sleep(pause)
    return picks


# ---------------------------------------------------------------------------- `pickplace up --processes`
async def run_processes(
    settings: Settings,
    cycles: int = 0,
    console: Any = None,
    ports: LocalPorts | None = None,
    drive: bool = True,
) -> list[Any]:
    """The whole cell as separate OS processes on loopback until Ctrl-C (or ``cycles`` picks)."""
    from rich.console import Console

    from gateway.security import generate_token

    console = console or Console()
    ports = ports or LocalPorts.from_settings(settings)
    token = settings.gateway.api_token.get_secret_value() if settings.gateway.api_token else generate_token()
    var = REPO_ROOT / "var"
    specs = topology(
        settings,
        ports,
        api_token=token,
        metrics_root=var / "metrics",
        log_dir=var / "log" / "processes",
        state_dir=var / "gateway",
    )

    def show(ev: LauncherEvent) -> None:
        colour = {"healthy": "green", "exited": "red", "restarting": "yellow", "gave-up": "red"}.get(
            ev.kind, "cyan"
        )
        console.print(f"[{colour}]{ev.service:9s} {ev.kind}[/{colour}] {ev.detail}")

    def on_pick(ev: Any) -> None:
        what = (
            "[green]success[/green]"
            if ev.success
            else f"[red]failed[/red] at {ev.stage_reached}: {ev.failure_reason[:80]}"
        )
        console.print(f"pick {ev.pick_id[:8]} {ev.object_class or '-'}: {what} in {ev.cycle_time_s:.1f} s")

    async with Launcher(
        settings, specs, ports, log_dir=var / "log" / "processes", metrics_root=var / "metrics", on_event=show
    ) as launcher:
        console.print(
            f"[bold]pickplace[/bold] cell [cyan]{settings.cell_id}[/cyan] as {len(specs)} processes; "
            f"dashboard http://127.0.0.1:{ports.gateway}/#token={token}; logs in {launcher.log_dir}; "
            "Ctrl-C stops them all"
        )
        if not drive:
            await asyncio.Event().wait()
        return await drive_cycles(launcher.settings, cycles, on_pick)
    return []  # pragma: no cover - the context manager above always returns or raises


# ---------------------------------------------------------------------------- `python -m services.apps.launcher`
app = typer.Typer(
    help="pickplace process launcher: health probes, cycle driver, local topology",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)


def _load(profile: str | None) -> Settings:
    try:
        return load_settings(profile)
    except ConfigurationError as exc:
        typer.echo(f"configuration error: {exc}", err=True)
        raise typer.Exit(2) from None


def _run_async(fn: Callable[[], Awaitable[Any]]) -> Any:
    with contextlib.suppress(asyncio.CancelledError):
        return run_until_signal(fn())
    return None


@app.command()
def health(
    service: Annotated[str, typer.Argument(help="one of: " + " | ".join(SERVICES))],
    timeout: Annotated[float, typer.Option(help="seconds")] = 3.0,
    profile: Annotated[str | None, typer.Option("--profile", "-p")] = None,
) -> None:
    """Exit 0 when the service answers (the Docker/Kubernetes probe), 1 with the reason when not."""
    s = _load(profile)
    try:
        typer.echo(asyncio.run(check_health(s, service, timeout)))
    except (RobotCommunicationError, ConfigurationError) as exc:
        typer.echo(f"unhealthy: {exc}", err=True)
        raise typer.Exit(1) from None


@app.command()
def drive(
    cycles: Annotated[int, typer.Option(help="pick cycles (0 = until stopped)")] = 0,
    profile: Annotated[str | None, typer.Option("--profile", "-p")] = None,
) -> None:
    """Enable the arm and run pick cycles through the task service, fresh twin scene between them."""
    from services.common.logs import setup_logging

    s = _load(profile)
    setup_logging(s.logging, console=True)
    _run_async(lambda: drive_cycles(s, cycles))


@app.command()
def up(
    cycles: Annotated[int, typer.Option(help="pick cycles (0 = until Ctrl-C)")] = 0,
    profile: Annotated[str | None, typer.Option("--profile", "-p")] = None,
) -> None:
    """Every service as its own OS process on loopback (what `pickplace up --processes` runs)."""
    from services.common.logs import setup_logging

    s = _load(profile)
    setup_logging(s.logging, console=False)
    _run_async(lambda: run_processes(s, cycles))


if __name__ == "__main__":
    app()
