"""Logs and the per-process Prometheus exporter."""

from __future__ import annotations

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
