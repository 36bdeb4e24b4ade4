"""Logs and the per-process Prometheus exporter."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from services.common.settings.base import Model, is_loopback


class MetricsSettings(Model):
    """A per-process Prometheus exporter (``/metrics``) for services without an HTTP server of their own.

    None = off (``pickplace up`` and the gateway serve metrics themselves). Deployments set
    ``PICKPLACE_METRICS__PORT`` (and ``PROMETHEUS_MULTIPROC_DIR``) per container.
    """

    host: str = "127.0.0.1"
    port: int | None = Field(None, ge=0, le=65535)
    allow_remote: bool = Field(False, description="a non-loopback bind address needs this")

    @model_validator(mode="after")
    def _loopback(self) -> MetricsSettings:
        if not self.allow_remote and not is_loopback(self.host):
            raise ValueError(f"metrics host {self.host!r} is not loopback (set metrics.allow_remote)")
        return self


class LoggingSettings(Model):
    level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    file: str | None = "var/log/pickplace.log"
    max_bytes: int = 10 * 1024 * 1024
    backups: int = 5


class StateSettings(Model):
    """Where a run keeps its files: the processes' metrics and logs, the gateway's spill file."""

    dir: str | None = Field(
        None, description="absolute, or relative to the checkout; default var/<cell_id>, one per cell"
    )
    session_log: bool = Field(True, description="each run also logs to session-<start time>.log")

    def path(self, cell_id: str, root: Path) -> Path:
        """This cell's state directory: another cell's (another cell_id) never overlaps it."""
        if self.dir is None:
            return root / "var" / cell_id
        p = Path(self.dir)
        return p if p.is_absolute() else root / p
