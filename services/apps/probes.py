"""What compose/Kubernetes call on a running service: the health probe
(``python -m services.apps.launcher health <service>``) and the per-process Prometheus exporter
(behind ``PICKPLACE_METRICS__PORT``)."""

from __future__ import annotations

import asyncio
import contextlib
import os
import urllib.request
from pathlib import Path
from typing import Any

from services.apps.topology import GRPC_SERVICES, MULTIPROC_ENV, SERVICES
from services.common.errors import ConfigurationError, RobotCommunicationError
from services.common.settings import Settings


def _dial_host(host: str) -> str:
    return "127.0.0.1" if host in ("0.0.0.0", "", "::") else host


async def accepts_connections(host: str, port: int, timeout_s: float, what: str) -> None:
    """A TCP connection to ``host:port`` is accepted (then closed); RobotCommunicationError naming
    ``what`` otherwise."""
    try:
        _r, w = await asyncio.wait_for(asyncio.open_connection(host, port), timeout_s)
    except (OSError, TimeoutError) as exc:
        raise RobotCommunicationError(f"{what} {host}:{port} not reachable: {exc}") from exc
    w.close()
    with contextlib.suppress(OSError):
        await w.wait_closed()


async def check_health(settings: Settings, service: str, timeout_s: float = 3.0) -> str:
    """Is ``service`` up and answering? Returns what was checked; raises RobotCommunicationError if not."""
    if service == "sim-dobot":
        host, port = _dial_host(settings.sim.host), settings.sim.dashboard_port
        await accepts_connections(host, port, timeout_s, "simulated Dobot dashboard")
        return f"sim-dobot dashboard {host}:{port} accepts connections"
    if service in GRPC_SERVICES:
        from services.common.grpc_util import check_health as grpc_health

        host = _dial_host(settings.grpc.client_host(service))  # type: ignore[arg-type]
        port = getattr(settings.grpc, f"{service}_port")
        return await grpc_health(host, port, service, timeout_s)  # the shell's state and its links
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
