"""``pickplace up --processes``: every child runs with the launcher's settings (its ``-c`` file, ``--task``,
``--seed``, overrides), not only the profile, while the topology's own values (ports, log files, the
token) still win in each child; the token is never written to disk.

Each child's settings are loaded here exactly as the child loads them: from its environment alone.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from services.apps.launcher import write_settings_layer
from services.apps.topology import GRPC_SERVICES, LocalPorts, topology
from services.common.modes import TaskKind
from services.common.settings import load_settings

TOKEN = "child-settings-token-0123456789"


def test_each_child_loads_the_launchers_settings_under_the_topologys_own(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    parent = load_settings(
        "sim",
        overrides={
            "task": {"task": "sort-cubes"},
            "sim": {"seed": 4242},
            "robot": {"speed_ratio": 37},
            "logging": {"file": str(tmp_path / "parent.log")},
            "metrics": {"port": 9464},  # the launcher's own: never every child's (they would collide)
            "gateway": {"api_token": TOKEN},
        },
    )
    path = write_settings_layer(parent, tmp_path / "cell" / "settings.yaml")
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert TOKEN not in path.read_text() and "api_token" not in path.read_text()

    ports = LocalPorts.free()
    log_dir = tmp_path / "log"
    specs = topology(parent, ports, api_token=TOKEN, log_dir=log_dir, settings_file=path)
    assert {sp.name for sp in specs} >= {"sim-dobot", *GRPC_SERVICES, "gateway"}
    for spec in specs:
        for name in [k for k in os.environ if k.startswith("PICKPLACE_")]:
            monkeypatch.delenv(name)
        for name, value in spec.env.items():
            monkeypatch.setenv(name, value)
        child = load_settings()
        # the launcher's settings ...
        assert child.task.task is TaskKind.SORT_CUBES, spec.name
        assert child.robot.speed_ratio == 37, spec.name
        assert child.sim.seed == 4242, spec.name
        # ... under the topology's: its ports, its log file per process, no shared metrics port
        assert child.logging.file == str(log_dir / f"{spec.name}.log"), spec.name
        assert child.metrics.port is None, spec.name
        assert child.zenoh.connect == [f"tcp/127.0.0.1:{ports.zenoh}"] and child.zenoh.listen == []
        for service in GRPC_SERVICES:
            assert getattr(child.grpc, f"{service}_port") == ports.grpc[service], (spec.name, service)
        if spec.name == "gateway":
            assert child.gateway.port == ports.gateway
        if spec.name != "sim-dobot":  # every gRPC service asks for the cell's token, from its environment
            assert child.gateway.api_token is not None
            assert child.gateway.api_token.get_secret_value() == TOKEN


def test_without_a_settings_file_a_child_runs_on_its_profile(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    parent = load_settings("sim", overrides={"robot": {"speed_ratio": 37}})
    (robot,) = [sp for sp in topology(parent, LocalPorts.free(), api_token=TOKEN) if sp.name == "robot"]
    for name in [k for k in os.environ if k.startswith("PICKPLACE_")]:
        monkeypatch.delenv(name)
    for name, value in robot.env.items():
        monkeypatch.setenv(name, value)
    assert load_settings().robot.speed_ratio == load_settings("sim").robot.speed_ratio != 37


def test_a_ur_cell_is_refused_with_a_clear_error() -> None:
    from services.common.errors import ConfigurationError

    ur = load_settings("sim", overrides={"robot": {"model": "ur5e", "driver": "ur_rtde"}})
    with pytest.raises(ConfigurationError, match=r"ur_rtde \(ur5e\).*pickplace up"):
        topology(ur, LocalPorts.free(), api_token=TOKEN)
