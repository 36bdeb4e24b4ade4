"""The root settings model and its loader: the YAML/profile/environment layering.

Sources, lowest priority first: ``config/default.yaml``, then the selected
profile ``config/profiles/<profile>.yaml``, then an optional extra YAML file,
then ``PICKPLACE_*`` environment variables (nested with ``__``, e.g.
``PICKPLACE_ROBOT__SPEED_RATIO=30``). Unsafe values are rejected here, before
any service starts: a speed ratio outside 1–100, a non-loopback robot address
in the sim profile, Zenoh multicast scouting, non-loopback defaults.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml
from pydantic import Field, ValidationError, model_validator
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from services.common.errors import ConfigurationError
from services.common.settings.base import is_loopback
from services.common.settings.database import DatabaseSettings
from services.common.settings.gateway import GatewaySettings
from services.common.settings.grasp import GraspSettings
from services.common.settings.gripper import GripperSettings
from services.common.settings.motion import MotionSettings
from services.common.settings.net import GrpcSettings, ZenohSettings
from services.common.settings.observability import LoggingSettings, MetricsSettings, StateSettings
from services.common.settings.record import RecordSettings
from services.common.settings.robot import KeyPoseCycleSettings, RobotSettings
from services.common.settings.sim import SimSettings
from services.common.settings.task import TaskSettings
from services.common.settings.vision import VisionSettings

REPO_ROOT = Path(__file__).resolve().parents[3]
CONFIG_DIR = Path(os.environ.get("PICKPLACE_CONFIG_DIR", REPO_ROOT / "config"))
PROFILE_ENV = "PICKPLACE_PROFILE"
CONFIG_FILE_ENV = "PICKPLACE_CONFIG_FILE"


class Settings(BaseSettings):
    model_config = SettingsConfigDict(
        env_prefix="PICKPLACE_", env_nested_delimiter="__", extra="forbid", validate_assignment=True
    )

    profile: str = "sim"
    cell_id: str = Field("cell1", pattern=r"^[A-Za-z0-9_\-]+$")
    robot: RobotSettings = RobotSettings()
    gripper: GripperSettings = GripperSettings()
    sim: SimSettings = SimSettings()
    zenoh: ZenohSettings = ZenohSettings()
    grpc: GrpcSettings = GrpcSettings()
    logging: LoggingSettings = LoggingSettings()
    cycle: KeyPoseCycleSettings = KeyPoseCycleSettings()
    motion: MotionSettings = MotionSettings()
    vision: VisionSettings = VisionSettings()
    grasp: GraspSettings = GraspSettings()
    database: DatabaseSettings = DatabaseSettings()
    gateway: GatewaySettings = GatewaySettings()
    task: TaskSettings = TaskSettings()
    metrics: MetricsSettings = MetricsSettings()
    record: RecordSettings = RecordSettings()
    state: StateSettings = StateSettings()

    @model_validator(mode="after")
    def _profile_safety(self) -> Settings:
        if self.profile == "sim" and not is_loopback(self.robot.host):
            raise ValueError(f"the sim profile must not name a robot address ({self.robot.host!r})")
        return self

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        # Explicit arguments win, then environment, then the YAML layers passed as init kwargs
        # by load_settings (they arrive through _YamlSource).
        return (init_settings, env_settings, _YamlSource(settings_cls))


_yaml_layers: list[dict[str, Any]] = []


class _YamlSource(PydanticBaseSettingsSource):
    def get_field_value(self, field: Any, field_name: str) -> tuple[Any, str, bool]:  # pragma: no cover
        return None, field_name, False

    def __call__(self) -> dict[str, Any]:
        merged: dict[str, Any] = {}
        for layer in _yaml_layers:
            merged = deep_merge(merged, layer)
        return merged


def deep_merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def read_yaml(path: Path) -> dict[str, Any]:
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except FileNotFoundError as exc:
        raise ConfigurationError(f"config file not found: {path}") from exc
    except yaml.YAMLError as exc:
        raise ConfigurationError(f"config file {path} is not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigurationError(f"config file {path} must hold a mapping, not {type(data).__name__}")
    return data


def load_settings(
    profile: str | None = None,
    config_file: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    config_dir: Path | None = None,
) -> Settings:
    """Build the validated settings; raise ConfigurationError naming every bad field."""
    cdir = config_dir or CONFIG_DIR
    profile = profile or os.environ.get(PROFILE_ENV) or "sim"
    layers = [read_yaml(cdir / "default.yaml")]
    profile_path = cdir / "profiles" / f"{profile}.yaml"
    if not profile_path.exists():
        known = sorted(p.stem for p in (cdir / "profiles").glob("*.yaml"))
        raise ConfigurationError(f"unknown profile {profile!r}; known profiles: {known}")
    layers.append(read_yaml(profile_path))
    extra = config_file or os.environ.get(CONFIG_FILE_ENV)
    if extra:
        layers.append(read_yaml(Path(extra)))
    layers.append({"profile": profile})
    if overrides:
        layers.append(overrides)
    global _yaml_layers
    _yaml_layers = layers
    try:
        return Settings()
    except ValidationError as exc:
        raise ConfigurationError(format_validation_error(exc)) from exc
    finally:
        _yaml_layers = []


def format_validation_error(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "settings"
        parts.append(f"{loc}: {err['msg']}")
    return "invalid configuration: " + "; ".join(parts)
