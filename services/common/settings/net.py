"""Transports between services: Zenoh and gRPC endpoints."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from services.common.settings.base import Model, endpoint_host, is_loopback


class ZenohSettings(Model):
    mode: Literal["peer", "client", "router"] = "peer"
    listen: list[str] = Field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    connect: list[str] = Field(default_factory=list)
    multicast_scouting: bool = False
    allow_remote: bool = False

    @model_validator(mode="after")
    def _safe(self) -> ZenohSettings:
        if self.multicast_scouting:
            raise ValueError("zenoh multicast scouting must stay off; give explicit endpoints")
        if not self.allow_remote:
            for ep in [*self.listen, *self.connect]:
                if not is_loopback(endpoint_host(ep)):
                    raise ValueError(f"zenoh endpoint {ep!r} is not loopback (set zenoh.allow_remote)")
        return self


class GrpcSettings(Model):
    host: str = "127.0.0.1"
    robot_port: int = Field(50051, ge=0, le=65535)
    motion_port: int = Field(50052, ge=0, le=65535)
    vision_port: int = Field(50053, ge=0, le=65535)
    grasp_port: int = Field(50054, ge=0, le=65535)
    task_port: int = Field(50055, ge=0, le=65535)
    request_timeout_s: float = Field(10.0, gt=0)
    # Where clients dial each service when it runs elsewhere (a compose/Kubernetes service name);
    # None = ``host``. The service itself always binds ``host``.
    robot_host: str | None = None
    motion_host: str | None = None
    vision_host: str | None = None
    grasp_host: str | None = None
    task_host: str | None = None

    def client_host(self, service: Literal["robot", "motion", "vision", "grasp", "task"]) -> str:
        """The address clients use for ``service``: its own host if set, else the shared bind host."""
        return getattr(self, f"{service}_host") or self.host
