"""The one shape of a service shell: an async context manager with an explicit state.

A shell (the robot driver, the planners, vision, the task runner, the simulated Dobot, the gateway's
HTTP server) is entered once, runs, and is left once::

    NEW ──enter──▶ STARTING ──▶ RUNNING ──exit──▶ STOPPING ──▶ STOPPED

Its background work runs in one :class:`asyncio.TaskGroup` (:meth:`ServiceShell.spawn`), which the
shell cancels and waits for before it releases anything else, so nothing outlives its service; a
background task that fails stops the service (the task group cancels the task that entered it) and
the failure is raised when the shell is left. Resources are entered on an :class:`AsyncExitStack`
in ``_start`` and released in reverse order. Misuse — entering twice, spawning or waiting on a
shell that is not running — raises :class:`ShellStateError`.

:class:`GrpcShell` adds the gRPC server every service has: built with the common interceptor,
bound, started, stopped with a short grace, and answering the standard ``grpc.health.v1`` check
from :meth:`ServiceShell.health` — the shell's state and the state of its links.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import logging
from collections.abc import Callable, Coroutine, Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, ClassVar, Self, TypeVar

import grpc.aio

from services.common import grpc_util
from services.common.bus import Bus
from services.common.grpc_util import cell_token as cell_token  # the services' shells pass it on
from services.common.live_config import LiveConfig, OnChange
from services.common.settings import Settings

log = logging.getLogger("pickplace.shell")

T = TypeVar("T")


class ShellState(enum.Enum):
    NEW = "new"  # built, not entered yet
    STARTING = "starting"
    RUNNING = "running"
    STOPPING = "stopping"
    STOPPED = "stopped"  # final: a shell is not restarted, a new one is built


class ShellStateError(RuntimeError):
    """A shell used out of order: entered twice, or used while it is not running."""


@dataclass(frozen=True)
class Health:
    """What a health probe sees: the shell's state and each of its links (name → up)."""

    state: ShellState
    links: Mapping[str, bool] = field(default_factory=dict)

    @property
    def serving(self) -> bool:
        return self.state is ShellState.RUNNING and all(self.links.values())

    def describe(self) -> str:
        parts = [self.state.value, *(f"{name} {'up' if up else 'DOWN'}" for name, up in self.links.items())]
        return ", ".join(parts)


class ServiceShell:
    """Base of every shell. Subclasses implement ``_start`` and may report ``links``."""

    kind: ClassVar[str] = "service"  # names the shell's tasks and messages ("robot", "vision", …)

    def __init__(self) -> None:
        self._state = ShellState.NEW
        self._stack: contextlib.AsyncExitStack | None = None
        self._group: asyncio.TaskGroup | None = None
        self._tasks: set[asyncio.Task[Any]] = set()
        self._stopped = asyncio.Event()

    # ------------------------------------------------------------------ state
    @property
    def state(self) -> ShellState:
        return self._state

    def require_running(self, doing: str = "use it") -> None:
        if self._state is not ShellState.RUNNING:
            raise ShellStateError(f"cannot {doing}: the {self.kind} service is {self._state.value}")

    def links(self) -> dict[str, bool]:
        """The shell's links and whether each is up (none by default)."""
        return {}

    def health(self) -> Health:
        return Health(self._state, self.links() if self._state is ShellState.RUNNING else {})

    # ------------------------------------------------------------------ background work
    def spawn(self, coro: Coroutine[Any, Any, T], name: str) -> asyncio.Task[T]:
        """Run ``coro`` in the shell's task group (while it starts or runs); it is cancelled on exit."""
        if self._group is None or self._state not in (ShellState.STARTING, ShellState.RUNNING):
            coro.close()
            raise ShellStateError(f"cannot start {name!r}: the {self.kind} service is {self._state.value}")
        task = self._group.create_task(coro, name=f"{self.kind}.{name}")
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    def follow_config(self, bus: Bus, settings: Settings, on_change: OnChange) -> LiveConfig:
        """Follow PUT /config over Zenoh in the shell's task group."""
        live = LiveConfig(bus, settings, on_change)
        self.spawn(live.run(), "live-config")
        return live

    async def wait(self) -> None:
        """Until the shell has stopped (``serve`` functions wait here until they are cancelled)."""
        self.require_running("wait on it")
        await self._stopped.wait()

    # ------------------------------------------------------------------ lifecycle
    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        """Enter the shell's resources on ``stack`` (released in reverse order) and spawn its work."""
        raise NotImplementedError

    async def _wind_down(self) -> None:
        """Ask the background work to end by itself (a graceful stop) before what is left is cancelled."""

    async def __aenter__(self) -> Self:
        if self._state is not ShellState.NEW:
            raise ShellStateError(
                f"the {self.kind} service is {self._state.value}: a shell is entered once (build a new one)"
            )
        self._state = ShellState.STARTING
        stack = contextlib.AsyncExitStack()
        self._group = await stack.enter_async_context(asyncio.TaskGroup())
        self._stack = stack
        try:
            await self._start(stack)
        except BaseException:
            await self._shutdown()
            raise
        self._state = ShellState.RUNNING
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._state in (ShellState.STOPPING, ShellState.STOPPED):
            return  # already stopped (a shell that offers ``stop()`` may have been stopped by it)
        await self._shutdown()

    async def _shutdown(self) -> None:
        """Cancel the background work, wait for it, then release the resources in reverse order."""
        self._state = ShellState.STOPPING
        stack, self._stack = self._stack, None
        try:
            await self._wind_down()
            for task in list(self._tasks):
                task.cancel()
            if self._tasks:
                await asyncio.wait(list(self._tasks))
            if stack is not None:
                # the resources' exits are not handed the caller's exception: the task group would
                # wrap it in an ExceptionGroup; it propagates from ``__aexit__`` unchanged instead
                await stack.aclose()
        except BaseExceptionGroup as group:
            # a background task failed: raise its error itself (one failure is the usual case)
            if len(group.exceptions) == 1:
                raise group.exceptions[0] from group
            raise
        finally:
            self._group = None
            self._state = ShellState.STOPPED
            self._stopped.set()


class GrpcShell(ServiceShell):
    """A shell that serves gRPC: one server per shell, the common interceptor, the health check."""

    GRACE_S = 0.5  # in-flight calls get this long to finish when the shell stops

    def __init__(self, host: str, port: int, token: str | None = None) -> None:
        """``token``: every call but the health check must carry it (``authorization: Bearer``);
        None serves anyone who can reach the port (a warning says so)."""
        super().__init__()
        self.grpc_host = host
        self.grpc_port = port  # the port asked for (0 = any free); the bound one once running
        self.grpc_token = token
        self.server: grpc.aio.Server | None = None

    async def _serve_grpc(
        self,
        stack: contextlib.AsyncExitStack,
        register: Callable[[grpc.aio.Server], object],
        what: str,
        interceptors: list[grpc.aio.ServerInterceptor] | None = None,
    ) -> int:
        """Build the server, let ``register`` add the servicers, bind, start; stopped on exit."""
        auth = [grpc_util.TokenAuthInterceptor(self.grpc_token)] if self.grpc_token else []
        if not auth:
            log.warning(
                "%s gRPC on %s:%s takes calls without a token: set gateway.api_token",
                self.kind,
                self.grpc_host,
                self.grpc_port,
            )
        server = grpc_util.create_server([*auth, *(interceptors or [])])
        register(server)
        grpc_util.add_health(server, self.health)
        self.grpc_port = grpc_util.bind(server, self.grpc_host, self.grpc_port)
        await server.start()
        self.server = server
        stack.push_async_callback(self._stop_server, server)
        log.info("%s serving %s on %s:%d", self.kind, what, self.grpc_host, self.grpc_port)
        return self.grpc_port

    async def _stop_server(self, server: grpc.aio.Server) -> None:
        await server.stop(grace=self.GRACE_S)
        self.server = None
