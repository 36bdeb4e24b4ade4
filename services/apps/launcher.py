"""``pickplace up --processes``: the deployed topology as separate OS processes on loopback.

Each service runs as its own process with exactly the command docker compose runs
(``pickplace serve <service>``, ``pickplace sim-dobot``) and the same ``PICKPLACE_*``
environment variable names, pointed at loopback ports instead of container names.
This process is the Zenoh rendezvous (a router session listening on loopback; the
services join as Zenoh clients, as they join the ``zenoh`` container in compose), it
serves each child's Prometheus metrics (the child writes them to its own
``PROMETHEUS_MULTIPROC_DIR``), restarts a child that dies (and says so), and on
Ctrl-C stops every child: SIGTERM, then SIGKILL after a grace period.

The processes and their environment come from :mod:`services.apps.topology`; this module's
command line (``python -m services.apps.launcher health|drive|up``) also serves the compose and
Kubernetes probes (:mod:`services.apps.probes`) and drives cycles (:mod:`services.apps.cycles`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import shutil
import signal
import time
from collections.abc import Awaitable, Callable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any

import typer
import yaml

from services.apps.cycles import drive_cycles
from services.apps.probes import accepts_connections, check_health, serve_metrics_dir
from services.apps.topology import (
    MULTIPROC_ENV,
    RECORD,
    SERVICES,
    LocalPorts,
    ProcessSpec,
    child_view,
    pickplace_program,
    settings_layer,
    topology,
)
from services.common.aio import run_until_signal
from services.common.errors import ConfigurationError, RobotCommunicationError
from services.common.settings import REPO_ROOT, Settings, load_settings

log = logging.getLogger("pickplace.launcher")

# the processes that store and record what the others publish: stopped once the others are gone
_CONSUMERS = frozenset({"gateway", RECORD})


# ---------------------------------------------------------------------------- the process supervisor
@dataclass
class Child:
    spec: ProcessSpec
    proc: asyncio.subprocess.Process | None = None
    restarts: int = 0
    exits: list[int] = field(default_factory=list)
    started_at: float = 0.0
    started_wall: float = 0.0  # time.time() at the start: files it writes are newer

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
        for group in (
            ("sim-dobot",),
            ("robot",),
            ("motion", "grasp", "vision", "task"),
            ("gateway",),
            (RECORD,),
        ):
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
        """SIGTERM the services that publish, then, once they are gone, the ones that store and record
        (gateway, recorder): a cycle's last record, or the interrupted one of a cycle cut by the stop,
        reaches the database before its writer stops. SIGKILL what is left after the grace."""
        self._stopping = True
        for t in self._watchers:
            t.cancel()
        await asyncio.gather(*self._watchers, return_exceptions=True)
        self._watchers.clear()
        deadline = time.monotonic() + self.stop_grace_s
        names = list(reversed([spec.name for spec in self.specs]))  # the reverse of the start order
        consumers = [n for n in names if n in _CONSUMERS]
        await self._stop_children([n for n in names if n not in _CONSUMERS], deadline)
        await self._stop_children(consumers, max(deadline, time.monotonic() + self.stop_grace_s / 2))
        for server in self._metrics_servers:
            with contextlib.suppress(Exception):
                server.shutdown()
                server.server_close()
        self._metrics_servers.clear()
        if self._router is not None:
            router, self._router = self._router, None
            with contextlib.suppress(Exception):
                await asyncio.to_thread(router.close)

    async def _stop_children(self, names: list[str], deadline: float) -> None:
        children = [self.children[n] for n in names if n in self.children]
        for child in children:
            if child.alive:
                assert child.proc is not None
                with contextlib.suppress(ProcessLookupError):
                    child.proc.send_signal(signal.SIGTERM)
        for child in children:
            if child.proc is None:
                continue
            try:
                await asyncio.wait_for(child.proc.wait(), max(0.1, deadline - time.monotonic()))
            except TimeoutError:
                log.warning("%s did not stop within %.0f s; killing it", child.spec.name, self.stop_grace_s)
                with contextlib.suppress(ProcessLookupError):
                    child.proc.kill()
                await child.proc.wait()

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
        child.started_at, child.started_wall = time.monotonic(), time.time()
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
                detail = await (
                    record_health(self.settings, child.spec.env, child.started_wall)
                    if name == RECORD
                    else check_health(self.settings, name, timeout_s=2.0)
                )
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


async def record_health(settings: Settings, env: dict[str, str], started_wall: float) -> str:
    """The record process is up when its Foxglove live view accepts connections, or (without one) when it
    has opened this run's first MCAP file under its directory."""
    port = int(env.get("PICKPLACE_RECORD__FOXGLOVE__PORT", "0"))
    if env.get("PICKPLACE_RECORD__FOXGLOVE__ENABLED") == "true" and port:
        host = settings.record.foxglove.host
        await accepts_connections(host, port, 2.0, "record: Foxglove live view")
        return f"record: Foxglove live view ws://{host}:{port} accepts connections"
    directory = Path(env["PICKPLACE_RECORD__DIR"])
    files = await asyncio.to_thread(
        lambda: [p for p in directory.glob("*.mcap") if p.stat().st_mtime >= started_wall - 1.0]
    )
    if not files:
        raise RobotCommunicationError(f"record: no MCAP file of this run under {directory} yet")
    return f"record: writing {max(files)}"


# ---------------------------------------------------------------------------- state and session log
def with_state_dir(settings: Settings) -> Settings:
    """The cell's files in its own state directory (``state.dir``, default var/<cell_id>) where the
    settings leave them at their shared defaults: the SQLite database and the gateway's spill file.
    A configured path is kept. Two cells on one checkout share neither."""
    from services.common.settings import DatabaseSettings
    from services.common.settings.gateway import GatewaySettings

    state = settings.state.path(settings.cell_id, REPO_ROOT)
    gw, db = settings.gateway, settings.database
    if gw.pick_spill_file == GatewaySettings.model_fields["pick_spill_file"].default:
        gw = gw.model_copy(update={"pick_spill_file": str(state / "gateway" / "pick_spill.jsonl")})
    if db.url == DatabaseSettings.model_fields["url"].default:
        db = db.model_copy(update={"url": f"sqlite+aiosqlite:///{state / 'pickplace.db'}"})
    return settings.model_copy(update={"gateway": gw, "database": db})


def session_log_path(settings: Settings, started: datetime, kind: str) -> Path:
    """``session-<kind>-<UTC start>.log`` beside the rotating main log (or in the state directory's
    log/ when there is no main log file)."""
    main = settings.logging.file
    if main:
        folder = Path(main).parent if Path(main).is_absolute() else (REPO_ROOT / main).parent
    else:
        folder = settings.state.path(settings.cell_id, REPO_ROOT) / "log"
    return folder / f"session-{settings.cell_id}-{kind}-{started.strftime('%Y%m%dT%H%M%SZ')}.log"


@contextlib.contextmanager
def session_log(settings: Settings, kind: str) -> Iterator[Path | None]:
    """One log file for this run alone (``state.session_log``), named by its start time; the root
    logger writes to it until the run ends."""
    if not settings.state.session_log:
        yield None
        return
    path = session_log_path(settings, datetime.now(UTC), kind)
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s"))
    handler.setLevel(settings.logging.level)
    root = logging.getLogger()
    root.addHandler(handler)
    logging.getLogger("pickplace.session").info(
        "session of cell %s (%s) started; state in %s",
        settings.cell_id,
        kind,
        settings.state.path(settings.cell_id, REPO_ROOT),
    )
    try:
        yield path
    finally:
        root.removeHandler(handler)
        handler.close()


# ---------------------------------------------------------------------------- `pickplace up --processes`
def write_settings_layer(settings: Settings, path: Path) -> Path:
    """The launcher's settings for its children (:func:`settings_layer`), written atomically, owner-only."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        yaml.safe_dump(settings_layer(settings), f, sort_keys=False)
    os.replace(tmp, path)
    return path


async def run_processes(
    settings: Settings,
    cycles: int = 0,
    console: Any = None,
    ports: LocalPorts | None = None,
    drive: bool = True,
) -> list[Any]:
    """The whole cell as separate OS processes on loopback until Ctrl-C (or ``cycles`` picks)."""
    from pydantic import SecretStr
    from rich.console import Console

    from gateway.security import generate_token

    console = console or Console()
    ports = ports or LocalPorts.from_settings(settings)
    token = settings.gateway.api_token.get_secret_value() if settings.gateway.api_token else generate_token()
    # the launcher's own calls (enable, cycles, park) carry the token its services ask for
    settings = settings.model_copy(
        update={"gateway": settings.gateway.model_copy(update={"api_token": SecretStr(token)})}
    )
    settings = with_state_dir(settings)
    var = settings.state.path(settings.cell_id, REPO_ROOT)  # this cell's own: never another cell's files
    settings_file = write_settings_layer(settings, var / "settings.yaml")
    specs = topology(
        settings,
        ports,
        api_token=token,
        metrics_root=var / "metrics",
        log_dir=var / "log" / "processes",
        state_dir=var / "gateway",
        task_state_dir=var,  # the task's cycle journal: a cycle cut by a crash is recorded on restart
        settings_file=settings_file,  # the children run with the launcher's settings, not the profile's
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

    with session_log(settings, "processes") as session:
        async with Launcher(
            settings,
            specs,
            ports,
            log_dir=var / "log" / "processes",
            metrics_root=var / "metrics",
            on_event=show,
        ) as launcher:
            console.print(
                f"[bold]pickplace[/bold] cell [cyan]{settings.cell_id}[/cyan] as {len(specs)} processes; "
                f"dashboard http://127.0.0.1:{ports.gateway}/#token={token}; logs in {launcher.log_dir}"
                + (f", this session's in {session}" if session else "")
                + "; Ctrl-C stops them all"
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
