"""The local topology, pure: which processes run, with which command and ``PICKPLACE_*`` environment,
on which loopback ports — the same commands and variable names docker compose and Kubernetes use."""

from __future__ import annotations

import contextlib
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from services.common.errors import ConfigurationError
from services.common.net import free_loopback_ports
from services.common.settings import CONFIG_FILE_ENV, Settings
from services.common.settings.robot import RobotDriverKind

# Start order: the simulated controller first (the robot driver connects to it), the gateway last.
SERVICES = ("sim-dobot", "robot", "motion", "grasp", "vision", "task", "gateway")
# The live view and recorder of the cell (``pickplace serve record``): a process of the local run when it
# records (``up --processes --record DIR``), started after the gateway; compose and Kubernetes leave it out.
RECORD = "record"
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
# Names only the local run sets: a per-process log file, a throw-away PostgreSQL schema (tests), the
# launcher's own settings as every child's config file.
LOCAL_ONLY_ENV = frozenset(
    {"PICKPLACE_LOGGING__FILE", "PICKPLACE_DATABASE__SCHEMA_NAME", "PICKPLACE_STATE__DIR", CONFIG_FILE_ENV}
)

DEFAULT_METRICS_PORTS = {
    "sim-dobot": 9100,
    "robot": 9101,
    "motion": 9102,
    "grasp": 9103,
    "vision": 9104,
    "task": 9105,
}
DEFAULT_ZENOH_PORT = 7447


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
    foxglove: int = 0  # the record process's live view (0: not served)

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
            foxglove=s.record.foxglove.port if s.record.foxglove.enabled else 0,
        )

    @classmethod
    def free(cls) -> LocalPorts:
        """All ports chosen free on 127.0.0.1 (tests; two runs side by side)."""
        ports = free_loopback_ports(13 + len(DEFAULT_METRICS_PORTS))
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
            foxglove=next(it),
        )

    def all(self) -> dict[str, int]:
        out = {
            "zenoh": self.zenoh,
            "gateway": self.gateway,
            "gateway-edge": self.edge,
            "sim-dashboard": self.sim_dashboard,
            "sim-feedback": self.sim_feedback,
            "sim-slow": self.sim_slow,
            "foxglove": self.foxglove,
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
    if name not in (*SERVICES, RECORD):
        raise ConfigurationError(f"unknown service {name!r}; the topology has {[*SERVICES, RECORD]}")
    return ("serve", name)


def settings_layer(settings: Settings) -> dict[str, object]:
    """The launcher's resolved settings as a config file for its children (``PICKPLACE_CONFIG_FILE``), so
    each child runs with what the launcher was given — its ``-c`` file, ``--task``, ``--seed`` and the
    ``PICKPLACE_*`` variables of its shell — and not only the profile; what the topology sets in a
    child's environment (ports, files) still wins. The profile is each child's own variable, the token
    travels in the environment (never on disk), and a log file or metrics port is each process's own."""
    return settings.model_dump(
        mode="json",
        exclude={"profile": True, "gateway": {"api_token"}, "logging": {"file"}, "metrics": {"port"}},
    )


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
    task_state_dir: Path | None = None,
    settings_file: Path | None = None,
) -> list[ProcessSpec]:
    """The child processes of the local run, in start order (pure: no I/O); the recorder last when
    ``record.dir`` is set."""
    if settings.robot.driver is not RobotDriverKind.DOBOT:
        raise ConfigurationError(
            f"the multi-process cell runs the simulated Dobot (sim-dobot); robot.driver "
            f"{settings.robot.driver.value} ({settings.robot.model}) is not wired into it yet: run a UR cell "
            "in one process (`pickplace up`, `pickplace eval --robot ur5e`)"
        )
    ports.check()
    common = {
        "PICKPLACE_PROFILE": settings.profile,
        "PICKPLACE_CELL_ID": settings.cell_id,
        "PICKPLACE_ZENOH__MODE": "client",
        "PICKPLACE_ZENOH__LISTEN": "[]",
        "PICKPLACE_ZENOH__CONNECT": json.dumps([f"tcp/127.0.0.1:{ports.zenoh}"]),
        **{f"PICKPLACE_GRPC__{name.upper()}_PORT": str(port) for name, port in ports.grpc.items()},
        **({CONFIG_FILE_ENV: str(settings_file)} if settings_file is not None else {}),
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
    if settings.record.dir:  # its Foxglove live view on the run's port, or none
        live = settings.record.foxglove.enabled and ports.foxglove > 0
        specific[RECORD] = {
            "PICKPLACE_RECORD__DIR": str(settings.record.dir),
            "PICKPLACE_RECORD__FOXGLOVE__ENABLED": json.dumps(live),
            **({"PICKPLACE_RECORD__FOXGLOVE__PORT": str(ports.foxglove)} if live else {}),
        }
    if settings.database.schema_name:
        specific["gateway"]["PICKPLACE_DATABASE__SCHEMA_NAME"] = settings.database.schema_name
    if task_state_dir is not None:  # the task's journal of the cycle in progress outlives the process here
        specific["task"] = {"PICKPLACE_STATE__DIR": str(task_state_dir)}
    specs = []
    for name in (*SERVICES, *((RECORD,) if RECORD in specific else ())):
        env = {**common, **specific.get(name, {})}
        if name != "sim-dobot":  # every gRPC service asks for the cell's token, every client sends it
            env["PICKPLACE_GATEWAY__API_TOKEN"] = api_token
        if log_dir is not None:
            env["PICKPLACE_LOGGING__FILE"] = str(log_dir / f"{name}.log")
        metrics_port = None
        # The gateway renders its own registry at /metrics; every other service writes to a directory
        # (the recorder has no metrics of its own).
        if name not in ("gateway", RECORD) and metrics_root is not None:
            env[MULTIPROC_ENV] = str(metrics_root / name)
            metrics_port = ports.metrics[name]
        specs.append(ProcessSpec(name, service_args(name), env, metrics_port))
    return specs


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
