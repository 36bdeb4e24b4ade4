"""The gateway: REST API, live updates, dashboard, authenticated gRPC edge."""

from __future__ import annotations

from pydantic import Field, SecretStr, field_validator, model_validator

from services.common.settings.base import Model, is_loopback


class GatewaySettings(Model):
    """REST API, live updates, dashboard, Prometheus metrics and the authenticated gRPC edge."""

    host: str = "127.0.0.1"
    port: int = Field(8080, ge=0, le=65535)
    allow_remote: bool = Field(False, description="a non-loopback bind address needs this")
    # Bearer token for mutating requests. No default anywhere: PICKPLACE_GATEWAY__API_TOKEN, or the
    # embedded local run generates one and prints it.
    api_token: SecretStr | None = None
    cors_origins: list[str] = Field(default_factory=list, description="empty = CORS closed")
    max_request_bytes: int = Field(65536, ge=1024, le=16 * 1024 * 1024)
    joint_state_rate_hz: float = Field(20.0, ge=0.1, le=125, description="joint states sent to browsers")
    robot_status_period_s: float = Field(0.5, ge=0.05, le=60)
    health_period_s: float = Field(10.0, ge=0.1, le=3600)
    status_period_s: float = Field(
        0.1, gt=0, le=10, description="GET /system/status snapshot: rebuilt at least this often"
    )
    status_db_period_s: float = Field(
        30.0,
        gt=0,
        le=600,
        description="how often the status snapshot re-reads today's picks besides after each write "
        "(each read holds the gateway's event loop for some ms)",
    )
    robot_id: str = Field("robot_01", pattern=r"^[A-Za-z0-9_\-]{1,50}$")
    pick_buffer_size: int = Field(
        1000, ge=1, le=1_000_000, description="picks held in memory while the DB is down"
    )
    pick_spill_file: str = Field("var/gateway/pick_spill.jsonl", description="overflow of that buffer")
    pick_batch_size: int = Field(100, ge=1, le=10_000)
    db_retry_initial_s: float = Field(0.2, gt=0, le=60)
    db_retry_max_s: float = Field(5.0, gt=0, le=600)
    rpc_timeout_s: float = Field(3.0, gt=0, le=60, description="start/stop relay to the task service")
    estop_timeout_s: float = Field(1.0, gt=0, le=10)
    edge_grpc_port: int | None = Field(
        50060, ge=0, le=65535, description="authenticated gRPC edge; None = off"
    )
    web_dir: str = "web"

    @field_validator("api_token")
    @classmethod
    def _token_strength(cls, v: SecretStr | None) -> SecretStr | None:
        if v is not None and len(v.get_secret_value()) < 16:
            raise ValueError(f"api_token must be at least 16 characters, got {len(v.get_secret_value())}")
        return v

    @model_validator(mode="after")
    def _bind(self) -> GatewaySettings:
        if not self.allow_remote and not is_loopback(self.host):
            raise ValueError(f"gateway host {self.host!r} is not loopback (set gateway.allow_remote)")
        if "*" in self.cors_origins:
            raise ValueError("gateway.cors_origins must list origins; '*' is refused")
        return self
