"""Running the gateway: uvicorn inside the caller's event loop, as an async context manager.

Used by ``pickplace serve gateway``, by the embedded ``pickplace up`` and by the tests. The
socket is bound before uvicorn starts, so the port (0 = any free) is known at once;
``__aenter__`` returns when the app's lifespan has finished starting, or raises what stopped it.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import socket
from collections.abc import AsyncIterator, Iterator
from typing import Any

import uvicorn
from fastapi import FastAPI

from services.common.errors import ConfigurationError, RobotCommunicationError
from services.common.settings import Settings
from services.common.shell import ServiceShell

log = logging.getLogger("pickplace.gateway.server")

STARTUP_TIMEOUT_S = 30.0


class _Server(uvicorn.Server):
    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        # the owner (the CLI's runner) handles SIGINT/SIGTERM by cancelling; uvicorn must not take them
        yield


class GatewayServer(ServiceShell):
    """uvicorn serving the app, as a shell: entered once the app's lifespan has started."""

    kind = "gateway"
    STOP_TIMEOUT_S = 10.0  # uvicorn's graceful shutdown (and the app's lifespan exit) gets this long

    def __init__(self, app: FastAPI, host: str = "127.0.0.1", port: int = 0):
        super().__init__()
        self.app = app
        self.host = host
        self.port = port
        self._server: _Server | None = None
        self._serving: asyncio.Task[None] | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        # IPPROTO_TCP explicitly: asyncio sets TCP_NODELAY only on sockets that say so, and without it
        # Nagle + delayed ACK add ~40 ms to every keep-alive response
        sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
        stack.callback(sock.close)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            raise RobotCommunicationError(f"gateway cannot listen on {self.host}:{self.port}: {exc}") from exc
        sock.listen(128)
        sock.setblocking(False)
        self.port = int(sock.getsockname()[1])
        config = uvicorn.Config(
            self.app,
            lifespan="on",
            log_level="warning",
            access_log=False,
            timeout_graceful_shutdown=3,
            ws_max_size=64 * 1024,
        )
        self._server = _Server(config)
        self._serving = self.spawn(self._serve(sock), "http")
        ready = self.spawn(self.app.state.ready.wait(), "ready")
        done, _ = await asyncio.wait(
            {self._serving, ready}, timeout=STARTUP_TIMEOUT_S, return_when=asyncio.FIRST_COMPLETED
        )
        if ready not in done:
            err = getattr(self.app.state, "startup_error", None)
            if err is not None:
                raise err
            raise ConfigurationError(f"gateway did not start within {STARTUP_TIMEOUT_S:.0f}s")
        log.info("gateway listening on %s", self.url)

    async def _serve(self, sock: socket.socket) -> None:
        assert self._server is not None
        try:
            await self._server.serve(sockets=[sock])
        except SystemExit:
            # uvicorn exits the process when the lifespan fails to start; here it is just a failed start
            log.debug("uvicorn stopped: startup failed")

    async def _wind_down(self) -> None:
        """uvicorn's own shutdown first, so the app's lifespan exits (buffered picks are written)."""
        if self._server is not None:
            self._server.should_exit = True
        if self._serving is not None and not self._serving.done():
            await asyncio.wait({self._serving}, timeout=self.STOP_TIMEOUT_S)

    async def wait(self) -> None:
        """Until the server stops (or the caller is cancelled)."""
        self.require_running("wait on it")
        assert self._serving is not None
        await asyncio.shield(self._serving)


def embedded_settings(settings: Settings) -> tuple[Settings, str]:
    """Settings for the local all-in-one run: a generated token (unless one is set), auto-migration.

    Returns the settings and the token to print.
    """
    from gateway.security import generate_token

    token = settings.gateway.api_token.get_secret_value() if settings.gateway.api_token else generate_token()
    gw = settings.gateway.model_copy(update={"api_token": _secret(token)})
    db = settings.database.model_copy(update={"auto_migrate": True})
    return settings.model_copy(update={"gateway": gw, "database": db}), token


def _secret(value: str) -> Any:
    from pydantic import SecretStr

    return SecretStr(value)


def dashboard_url(server: GatewayServer, token: str | None = None) -> str:
    """The address to open; the token travels in the fragment, which browsers never send to a server."""
    return f"{server.url}/" + (f"#token={token}" if token else "")


@contextlib.asynccontextmanager
async def embedded_gateway(
    settings: Settings, bus: Any, calibration_executor: Any = None, metrics_registries: Any = ()
) -> AsyncIterator[tuple[GatewayServer, str]]:
    """The gateway inside ``pickplace up``: shares the cell's Zenoh bus, SQLite migrated on start,
    a generated token, and exports the other services' metrics registries (``metrics_registries``).
    Yields the server and the dashboard URL to print (token in its fragment)."""
    from gateway.app import create_app

    gs, token = embedded_settings(settings)
    app = create_app(
        gs, bus=bus, calibration_executor=calibration_executor, metrics_registries=metrics_registries
    )
    async with GatewayServer(app, gs.gateway.host, gs.gateway.port) as server:
        yield server, dashboard_url(server, token)


async def serve(settings: Settings) -> None:
    """``pickplace serve gateway``: run until cancelled. Refuses an unmigrated database."""
    from gateway.app import create_app

    app = create_app(settings)
    async with GatewayServer(app, settings.gateway.host, settings.gateway.port) as server:
        log.info("dashboard and API on %s (docs at /docs)", server.url)
        settle_heap()
        await server.wait()


def settle_heap() -> None:
    """What start-up built (modules, the app, the clients) lives until the process ends: collected once
    and moved out of the collector's view, so a full collection later walks only what the running
    gateway allocates (one over the whole start-up heap held the event loop for 190-240 ms of CPU)."""
    gc.collect()
    gc.freeze()
