"""The deployment files, checked against the code (no Docker engine here): docker-compose.yml,
the Prometheus config, the Grafana provisioning and dashboard, the Kubernetes manifests."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import typer
import yaml
from pydantic import BaseModel

from services.apps.topology import (
    CONTAINER_ONLY_ENV,
    DEFAULT_METRICS_PORTS,
    LOCAL_ONLY_ENV,
    MULTIPROC_ENV,
    SERVICES,
    LocalPorts,
    service_args,
    topology,
)
from services.common.settings import Settings, load_settings
from tests.conftest import free_port
from tests.deploy.promtext import REPO, dashboards, exposition_names, panels, queried_metrics, query_exprs

COMPOSE = yaml.safe_load((REPO / "docker-compose.yml").read_text())
CSERVICES: dict[str, dict[str, Any]] = COMPOSE["services"]
IMAGE = "${PICKPLACE_IMAGE:-pickplace:latest}"
PICKPLACE_SERVICES = [n for n, s in CSERVICES.items() if s.get("image") == IMAGE]
NON_SETTINGS_ENV = {MULTIPROC_ENV, "MUJOCO_GL"}
VAR = re.compile(r"\$\{([A-Z_]+)(?::?[-?]([^}]*))?\}")
K8S_DIR = REPO / "deploy" / "k8s"


def interpolate(value: str) -> str:
    """Compose's ${VAR:-default} / ${VAR:?error} / ${VAR} with a stand-in for the .env secrets."""

    def sub(m: re.Match[str]) -> str:
        if m.group(0).startswith("${" + m.group(1) + ":-"):
            return m.group(2)
        return "x" * 24  # a secret from .env

    return VAR.sub(sub, str(value))


def settings_field(env_name: str) -> bool:
    """Does ``PICKPLACE_A__B__C`` name a field of the settings model?"""
    if not env_name.startswith("PICKPLACE_"):
        return False
    model: Any = Settings
    for part in env_name.removeprefix("PICKPLACE_").lower().split("__"):
        if model is None:  # a scalar field has no sub-fields
            return False
        fields = model.model_fields
        if part not in fields:
            return False
        ann = fields[part].annotation
        model = ann if isinstance(ann, type) and issubclass(ann, BaseModel) else None
    return True


def click_resolve(app: typer.Typer, args: list[str]) -> tuple[Any, dict[str, Any]]:
    """Parse ``args`` as the CLI would (unknown commands or options raise); returns the command and params.

    Typer carries its own copy of click, so groups are recognised by what they do, not by class."""
    cmd = typer.main.get_command(app)
    rest = list(args)
    ctx = cmd.make_context("pickplace", [], resilient_parsing=True)
    while hasattr(cmd, "get_command"):
        assert rest, f"{args} stops at a command group"
        name, rest = rest[0], rest[1:]
        sub = cmd.get_command(ctx, name)
        assert sub is not None, f"no command {name!r} in {args}"
        cmd = sub
        if hasattr(cmd, "get_command"):
            ctx = cmd.make_context(name, [], parent=ctx, resilient_parsing=True)
    parsed = cmd.make_context(cmd.name or "", rest, parent=ctx)
    return cmd, parsed.params


def cli_for(service: dict[str, Any]) -> tuple[typer.Typer, list[str]]:
    from services.apps import launcher
    from services.apps.cli import app

    entry = service.get("entrypoint")
    if entry == ["python", "-m", "services.apps.launcher"]:
        return launcher.app, list(service["command"])
    assert entry is None, f"unexpected entrypoint {entry}"
    return app, list(service["command"])  # the image's ENTRYPOINT is `pickplace`


# ---------------------------------------------------------------------------- compose
def test_compose_has_the_whole_cell():
    assert {"zenoh", "postgres", "prometheus", "grafana", *SERVICES} <= set(CSERVICES)
    assert set(SERVICES) <= set(PICKPLACE_SERVICES)
    dockerfile = (REPO / "deploy" / "docker" / "Dockerfile").read_text()
    assert 'ENTRYPOINT ["pickplace"]' in dockerfile and "USER pickplace" in dockerfile
    assert "MUJOCO_GL=egl" in dockerfile and dockerfile.count("FROM ") >= 2  # multi-stage
    assert COMPOSE["x-image"]["build"]["dockerfile"] == "deploy/docker/Dockerfile"


@pytest.mark.parametrize("name", PICKPLACE_SERVICES)
def test_every_compose_command_exists_in_the_cli(name):
    app, args = cli_for(CSERVICES[name])
    _cmd, params = click_resolve(app, args)
    if args[0] == "serve":
        from services.apps.cli import SERVICES as SERVE

        assert params["service"] in SERVE
    if name in SERVICES:
        assert tuple(args) == service_args(name), (
            "compose and `pickplace up --processes` run different commands"
        )


def test_an_unknown_command_is_caught_by_the_resolver():
    from services.apps.cli import app

    with pytest.raises(Exception, match="No such option"):
        click_resolve(app, ["sim-dobot", "--no-such-option"])
    with pytest.raises(AssertionError):
        click_resolve(app, ["serve-everything"])


@pytest.mark.parametrize("name", PICKPLACE_SERVICES)
def test_every_compose_variable_is_read_by_the_settings_and_valid(name, monkeypatch):
    env = {k: interpolate(v) for k, v in CSERVICES[name]["environment"].items()}
    unknown = [k for k in env if k not in NON_SETTINGS_ENV and not settings_field(k)]
    assert not unknown, f"{name} sets variables no setting reads: {unknown}"
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    s = load_settings()  # the container's settings validate (remote zenoh/gateway allowed explicitly)
    assert s.zenoh.connect == ["tcp/zenoh:7447"] and s.zenoh.mode == "client"
    assert s.grpc.client_host("vision") == "vision" and s.grpc.client_host("robot") == "sim-dobot"


def test_the_settings_field_check_rejects_a_misspelt_variable():
    assert settings_field("PICKPLACE_GRPC__ROBOT_PORT") and settings_field("PICKPLACE_PROFILE")
    assert not settings_field("PICKPLACE_GRPC__ROBOT_PROT") and not settings_field(
        "PICKPLACE_GRPC__ROBOT_PORT__X"
    )


def test_compose_and_the_local_launcher_use_the_same_variable_names():
    s = load_settings("sim")
    specs = {
        sp.name: sp
        for sp in topology(
            s,
            LocalPorts.from_settings(s),
            api_token="t" * 20,
            metrics_root=Path("/tmp/m"),
            log_dir=Path("/tmp/l"),
        )
    }
    for name in SERVICES:
        compose_names = set(CSERVICES[name]["environment"])
        local_names = set(specs[name].env)
        assert local_names - compose_names <= LOCAL_ONLY_ENV, (name, local_names - compose_names)
        assert compose_names - local_names <= CONTAINER_ONLY_ENV | {MULTIPROC_ENV}, (
            name,
            compose_names - local_names,
        )
        if name != "gateway":
            assert (
                int(CSERVICES[name]["environment"]["PICKPLACE_METRICS__PORT"]) == DEFAULT_METRICS_PORTS[name]
            )


def listening_ports(name: str) -> set[int]:
    env = {k: interpolate(v) for k, v in CSERVICES[name].get("environment", {}).items()}
    own = {
        "robot": ["PICKPLACE_GRPC__ROBOT_PORT"],
        "motion": ["PICKPLACE_GRPC__MOTION_PORT"],
        "grasp": ["PICKPLACE_GRPC__GRASP_PORT"],
        "vision": ["PICKPLACE_GRPC__VISION_PORT"],
        "task": ["PICKPLACE_GRPC__TASK_PORT"],
        "sim-dobot": [
            "PICKPLACE_SIM__DASHBOARD_PORT",
            "PICKPLACE_SIM__FEEDBACK_PORT",
            "PICKPLACE_SIM__SLOW_FEEDBACK_PORT",
        ],
        "gateway": ["PICKPLACE_GATEWAY__PORT", "PICKPLACE_GATEWAY__EDGE_GRPC_PORT"],
    }.get(name, [])
    ports = {int(env[k]) for k in own}
    if "PICKPLACE_METRICS__PORT" in env:
        ports.add(int(env["PICKPLACE_METRICS__PORT"]))
    return ports


def test_ports_do_not_clash():
    published = [
        p.rsplit(":", 1)[0].rsplit(":", 1)[-1] for s in CSERVICES.values() for p in s.get("ports", [])
    ]
    assert len(published) == len(set(published)), published
    namespaces: dict[str, list[int]] = {}
    for name in PICKPLACE_SERVICES:
        mode = CSERVICES[name].get("network_mode", "")
        ns = mode.removeprefix("service:") if mode.startswith("service:") else name
        namespaces.setdefault(ns, []).extend(listening_ports(name))
    for ns, ports in namespaces.items():
        assert len(ports) == len(set(ports)), f"port clash in the {ns} network namespace: {sorted(ports)}"
    assert set(namespaces["sim-dobot"]) >= {29999, 30004, 50051}  # the driver reaches the twin on loopback
    LocalPorts.from_settings(load_settings("sim")).check()  # the local defaults too
    with pytest.raises(Exception, match="port 7447"):
        LocalPorts(7447, {"robot": 7447}, 8080, 0, 1, 2, 3, {}).check()


def test_healthchecks_use_the_probe_command_and_dependencies_wait_for_health():
    from services.apps import launcher

    for name in SERVICES:
        test = CSERVICES[name]["healthcheck"]["test"]
        assert test[:4] == ["CMD", "python", "-m", "services.apps.launcher"]
        _cmd, params = click_resolve(launcher.app, test[4:])
        assert params["service"] == name
    for name in PICKPLACE_SERVICES:
        for dep, cond in CSERVICES[name].get("depends_on", {}).items():
            if "healthcheck" in CSERVICES[dep]:
                assert cond["condition"] == "service_healthy", (name, dep)
    assert CSERVICES["gateway"]["depends_on"]["db-migrate"]["condition"] == "service_completed_successfully"


def run_probe(service: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    import os

    full = {k: v for k, v in os.environ.items() if not k.startswith("PICKPLACE_")} | env
    return subprocess.run(
        [sys.executable, "-m", "services.apps.launcher", "health", service, "--timeout", "2"],
        env=full,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )


@pytest.mark.integration
async def test_the_health_probe_passes_on_a_serving_service_and_fails_without_one():
    import asyncio

    from services.motion.service import MotionService

    port = free_port()
    s = load_settings("sim", overrides={"grpc": {"motion_port": port}})
    async with MotionService(s) as svc:
        ok = await asyncio.to_thread(run_probe, "motion", {"PICKPLACE_GRPC__MOTION_PORT": str(svc.grpc_port)})
    bad = await asyncio.to_thread(run_probe, "motion", {"PICKPLACE_GRPC__MOTION_PORT": str(free_port())})
    assert ok.returncode == 0, ok.stderr
    assert bad.returncode == 1 and "unhealthy" in bad.stderr and "motion" in bad.stderr


def test_no_secret_is_committed():
    pg = CSERVICES["postgres"]["environment"]["POSTGRES_PASSWORD"]
    assert pg.startswith("${POSTGRES_PASSWORD:?"), "the password must come from .env, with no default"
    assert CSERVICES["gateway"]["environment"]["PICKPLACE_GATEWAY__API_TOKEN"].startswith(
        "${PICKPLACE_API_TOKEN:?"
    )
    assert "pgdata" in COMPOSE["volumes"] and any("pgdata:" in v for v in CSERVICES["postgres"]["volumes"])
    example = dict(
        line.split("=", 1)
        for line in (REPO / ".env.example").read_text().splitlines()
        if line and not line.startswith("#")
    )
    assert set(example) >= {"POSTGRES_PASSWORD", "GRAFANA_ADMIN_PASSWORD", "PICKPLACE_API_TOKEN"}
    assert all(v == "" for v in example.values())
    assert ".env" in (REPO / ".gitignore").read_text().splitlines()


# ---------------------------------------------------------------------------- prometheus
def test_prometheus_scrapes_every_service_port():
    cfg = yaml.safe_load((REPO / "deploy" / "prometheus" / "prometheus.yml").read_text())
    targets = {t for job in cfg["scrape_configs"] for sc in job["static_configs"] for t in sc["targets"]}
    expected = {"gateway:8080"}
    for name in SERVICES:
        env = CSERVICES[name]["environment"]
        if "PICKPLACE_METRICS__PORT" in env:
            mode = CSERVICES[name].get("network_mode", "")
            host = mode.removeprefix("service:") if mode.startswith("service:") else name
            expected.add(f"{host}:{env['PICKPLACE_METRICS__PORT']}")
    assert targets == expected
    assert (
        "./deploy/prometheus/prometheus.yml:/etc/prometheus/prometheus.yml:ro"
        in CSERVICES["prometheus"]["volumes"]
    )


# ---------------------------------------------------------------------------- grafana
def exported_by_the_code() -> set[str]:
    """Every metric family the services declare: the LLD set and the planners' own histograms."""
    import prometheus_client

    import services.grasp.service
    import services.motion.service  # noqa: F401 - they register their planning metrics on import
    from services.common.metrics import CellMetrics

    text = prometheus_client.generate_latest(CellMetrics().registry).decode()
    text += prometheus_client.generate_latest(prometheus_client.REGISTRY).decode()
    return exposition_names(text)


def test_grafana_provisioning_and_dashboard_are_valid():
    prov = REPO / "deploy" / "grafana" / "provisioning"
    ds = yaml.safe_load((prov / "datasources" / "prometheus.yml").read_text())["datasources"][0]
    assert ds["type"] == "prometheus" and ds["url"] == "http://prometheus:9090"
    provider = yaml.safe_load((prov / "dashboards" / "pickplace.yml").read_text())["providers"][0]
    mounts = CSERVICES["grafana"]["volumes"]
    assert f"./deploy/grafana/dashboards:{provider['options']['path']}:ro" in mounts
    assert "./deploy/grafana/provisioning:/etc/grafana/provisioning:ro" in mounts
    boards = dashboards()
    assert "pickplace.json" in boards
    for board in boards.values():
        ps = panels(board)
        ids = [p["id"] for p in ps]
        assert len(ids) == len(set(ids))
        for p in ps:
            for t in p.get("targets", []):
                assert t["datasource"]["uid"] == ds["uid"]
                assert queried_metrics(t["expr"]), f"panel {p['title']!r} selects no metric: {t['expr']}"
    titles = " | ".join(p["title"].lower() for p in panels(boards["pickplace.json"]))
    for topic in (
        "picks per minute",
        "success rate",
        "cycle time histogram",
        "cycle time percentiles",
        "vision latency",
        "planning latency",
        "joint positions",
        "robot mode",
        "emergency stops",
    ):
        assert topic in titles, topic


def test_every_dashboard_metric_is_exported_by_the_code():
    exported = exported_by_the_code()
    queried = {m for d in dashboards().values() for e in query_exprs(d) for m in queried_metrics(e)}
    assert queried - exported == set(), f"queried but never exported: {sorted(queried - exported)}"
    assert "nonexistent_metric_total" not in exported  # the check can fail


# ---------------------------------------------------------------------------- kubernetes
def k8s_docs() -> list[dict[str, Any]]:
    docs = []
    for path in sorted(K8S_DIR.glob("*.yaml")):
        docs.extend(d for d in yaml.safe_load_all(path.read_text()) if d)
    return docs


def test_k8s_manifests_parse_and_are_listed():
    docs = k8s_docs()
    kinds = {d["kind"] for d in docs}
    assert {"Deployment", "Service", "ConfigMap", "Secret", "PersistentVolumeClaim", "Job"} <= kinds
    kust = yaml.safe_load((K8S_DIR / "kustomization.yaml").read_text())
    listed = set(kust["resources"])
    assert listed == {p.name for p in K8S_DIR.glob("[0-9]*.yaml")}
    assert "secret.template.yaml" not in listed
    secret = next(d for d in docs if d["kind"] == "Secret")
    assert all("REPLACE_ME" in v for v in secret["stringData"].values())
    pg = next(d for d in docs if d["kind"] == "Deployment" and d["metadata"]["name"] == "postgres")
    pvc = next(d for d in docs if d["kind"] == "PersistentVolumeClaim")
    claims = [v["persistentVolumeClaim"]["claimName"] for v in pg["spec"]["template"]["spec"]["volumes"]]
    assert claims == [pvc["metadata"]["name"]]
    assert "realsense" in (K8S_DIR / "30-vision.yaml").read_text().lower()


def test_k8s_runs_the_same_image_commands_and_variables_as_compose():
    docs = k8s_docs()
    config = next(d for d in docs if d["kind"] == "ConfigMap" and d["metadata"]["name"] == "pickplace-env")[
        "data"
    ]
    assert set(config) == set(COMPOSE["x-env"])
    services = {d["metadata"]["name"] for d in docs if d["kind"] == "Service"}
    for key, host in config.items():
        if key.endswith("_HOST") and key.startswith("PICKPLACE_GRPC__") and key != "PICKPLACE_GRPC__HOST":
            assert host in services, f"{key}={host} names no Kubernetes Service"
    assert "zenoh" in services and config["PICKPLACE_ZENOH__CONNECT"] == '["tcp/zenoh:7447"]'
    images = set()
    seen = set()
    for d in docs:
        if d["kind"] not in ("Deployment", "Job"):
            continue
        for c in d["spec"]["template"]["spec"]["containers"]:
            if c["name"] not in PICKPLACE_SERVICES:
                continue
            seen.add(c["name"])
            images.add(c["image"])
            compose = CSERVICES[c["name"]]
            assert c["args"] == compose["command"], c["name"]
            assert c.get("command") == compose.get("entrypoint"), c["name"]
            names = set(config) | {e["name"] for e in c.get("env", [])}
            assert names == set(compose["environment"]) | set(config), c["name"]
            unknown = [n for n in names if n not in NON_SETTINGS_ENV and not settings_field(n)]
            assert not unknown, (c["name"], unknown)
            for e in c.get("env", []):
                assert isinstance(e.get("value", ""), str), (c["name"], e)
            if c["name"] in SERVICES:
                probe = c["readinessProbe"]["exec"]["command"]
                assert probe == CSERVICES[c["name"]]["healthcheck"]["test"][1:]
    assert seen == set(PICKPLACE_SERVICES)
    assert images == {"pickplace:latest"} == {IMAGE.split(":-", 1)[1].rstrip("}")}
    zenoh_cm = next(d for d in docs if d["kind"] == "ConfigMap" and d["metadata"]["name"] == "zenoh-config")
    assert zenoh_cm["data"]["zenoh.json5"] == (REPO / "deploy" / "zenoh" / "zenoh.json5").read_text()


def test_dashboard_json_is_plain_json():
    for path in (REPO / "deploy" / "grafana" / "dashboards").glob("*.json"):
        json.loads(path.read_text())


# ---------------------------------------------------------------------------- what a real engine found (issue 16)
METRICS_DIR = "/tmp/pickplace-metrics"


def image_uid() -> int:
    m = re.search(r"useradd [^\n]*--uid (\d+)", (REPO / "deploy" / "docker" / "Dockerfile").read_text())
    assert m, "the Dockerfile creates no user with a fixed uid"
    return int(m.group(1))


def k8s_containers() -> dict[str, dict[str, Any]]:
    return {
        c["name"]: c
        for d in k8s_docs()
        if d["kind"] in ("Deployment", "Job")
        for c in d["spec"]["template"]["spec"]["containers"]
    }


def k8s_env(container: dict[str, Any]) -> dict[str, Any]:
    return {e["name"]: e.get("value") for e in container.get("env", [])}


def test_the_metrics_tmpfs_belongs_to_the_image_user():
    uid = image_uid()
    exporters = [n for n in PICKPLACE_SERVICES if "PICKPLACE_METRICS__PORT" in CSERVICES[n]["environment"]]
    assert set(exporters) == set(DEFAULT_METRICS_PORTS)
    for name in exporters:
        mounts = [t for t in CSERVICES[name].get("tmpfs", []) if t.split(":", 1)[0] == METRICS_DIR]
        assert len(mounts) == 1, (name, CSERVICES[name].get("tmpfs"))
        opts = (
            dict(o.split("=", 1) for o in mounts[0].split(":", 1)[1].split(",")) if ":" in mounts[0] else {}
        )
        # a tmpfs is root's, whatever its mode: the non-root service could not write counter_*.db
        assert opts.get("uid") == str(uid) and opts.get("gid") == str(uid), (name, mounts[0])
    for name, c in k8s_containers().items():
        if name not in PICKPLACE_SERVICES:
            continue
        assert c["securityContext"]["runAsUser"] == uid, name
        if name in exporters:
            mounted = {m["mountPath"] for m in c.get("volumeMounts", [])}
            assert METRICS_DIR in mounted, name  # an emptyDir is world-writable


def test_the_multiprocess_dir_is_set_only_where_metrics_are_served_and_never_empty():
    # prometheus_client switches to multi-process mode when the name exists at all, even empty
    assert MULTIPROC_ENV not in COMPOSE["x-env"]
    for name, svc in CSERVICES.items():
        env = svc.get("environment", {})
        if name in PICKPLACE_SERVICES:
            assert (MULTIPROC_ENV in env) == ("PICKPLACE_METRICS__PORT" in env), name
        if MULTIPROC_ENV in env:
            assert env[MULTIPROC_ENV] == METRICS_DIR, (name, env[MULTIPROC_ENV])
    assert MULTIPROC_ENV not in CSERVICES["gateway"]["environment"]
    config = next(
        d for d in k8s_docs() if d["kind"] == "ConfigMap" and d["metadata"]["name"] == "pickplace-env"
    )
    assert MULTIPROC_ENV not in config["data"]
    for name, c in k8s_containers().items():
        if name not in PICKPLACE_SERVICES:
            continue
        env = k8s_env(c)
        assert (MULTIPROC_ENV in env) == ("PICKPLACE_METRICS__PORT" in env), name
        if MULTIPROC_ENV in env:
            assert env[MULTIPROC_ENV] == METRICS_DIR, (name, env[MULTIPROC_ENV])


def starts_an_exporter(service: dict[str, Any]) -> bool:
    """Does the command this container runs start the metrics exporter (``start_metrics_exporter``)?"""
    import inspect

    app, args = cli_for(service)
    cmd, _params = click_resolve(app, args)
    return "start_metrics_exporter(" in inspect.getsource(cmd.callback)


def test_every_prometheus_target_has_an_exporter():
    cfg = yaml.safe_load((REPO / "deploy" / "prometheus" / "prometheus.yml").read_text())
    for job in cfg["scrape_configs"]:
        for target in (t for sc in job["static_configs"] for t in sc["targets"]):
            host, port = target.rsplit(":", 1)
            # the containers in that host's network namespace, and which of them listens on the port
            inside = [
                n
                for n in PICKPLACE_SERVICES
                if n == host or CSERVICES[n].get("network_mode") == f"service:{host}"
            ]
            owners = [
                n
                for n in inside
                if port
                in (
                    CSERVICES[n]["environment"].get("PICKPLACE_METRICS__PORT"),
                    CSERVICES[n]["environment"].get("PICKPLACE_GATEWAY__PORT"),
                )
            ]
            assert len(owners) == 1, f"{job['job_name']} scrapes {target}; listening there: {owners}"
            owner = CSERVICES[owners[0]]
            if owner["environment"].get("PICKPLACE_GATEWAY__PORT") != port:
                assert starts_an_exporter(owner), f"{owners[0]} serves no metrics on {port}"
    # the check can fail: a command that starts no exporter
    assert not starts_an_exporter({"command": ["db", "upgrade"]})


def test_cell_driver_probes_itself_and_the_image_bakes_in_no_probe():
    from services.apps import launcher

    dockerfile = (REPO / "deploy" / "docker" / "Dockerfile").read_text()
    # an image-wide HEALTHCHECK is inherited by every service that sets none (the gateway's, on the driver)
    assert not re.search(r"^HEALTHCHECK", dockerfile, re.M)
    driver = CSERVICES["cell-driver"]["healthcheck"]
    assert not driver.get("disable") and driver["test"][:4] == [
        "CMD",
        "python",
        "-m",
        "services.apps.launcher",
    ]
    _cmd, params = click_resolve(launcher.app, driver["test"][4:])
    assert params["service"] == "task"  # what it drives, reached from its own container
    k8s = k8s_containers()["cell-driver"]
    assert k8s["readinessProbe"]["exec"]["command"] == driver["test"][1:]
    for name in PICKPLACE_SERVICES:
        if CSERVICES[name].get("restart") != "no":  # everything long-lived says when it is healthy
            hc = CSERVICES[name].get("healthcheck", {})
            assert hc.get("test") and not hc.get("disable"), name


def test_the_image_builds_from_argument_bases_with_a_small_context():
    dockerfile = (REPO / "deploy" / "docker" / "Dockerfile").read_text()
    assert not re.search(
        r"^# *syntax=", dockerfile, re.M
    )  # BuildKit would fetch that frontend from Docker Hub
    args = dict(re.findall(r"^ARG (\w+)=(\S+)$", dockerfile, re.M))
    assert args == {"NODE_IMAGE": "node:20-bookworm-slim", "PYTHON_IMAGE": "python:3.11-slim-bookworm"}
    stages = re.findall(r"^FROM (\S+) AS (\w+)$", dockerfile, re.M)
    assert [base for base, _ in stages] == ["${NODE_IMAGE}", "${PYTHON_IMAGE}", "${PYTHON_IMAGE}"]
    ignored = set((REPO / ".dockerignore").read_text().split())
    assert {".venv", ".git", ".env", "node_modules", "var"} <= ignored
    for copied in ("services", "gateway", "proto", "config", "web", "pyproject.toml", "README.md"):
        assert copied not in ignored


# ---------------------------------------------------------------------------- make compose-smoke
def smoke_module() -> Any:
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "compose_smoke", REPO / "deploy" / "compose-smoke" / "smoke.py"
    )
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("compose_smoke", module)
    spec.loader.exec_module(module)
    return module


def test_the_smoke_stand_ins_replace_only_third_party_images():
    smoke = smoke_module()
    override = yaml.safe_load((REPO / "deploy" / "compose-smoke" / "standins.yml").read_text())["services"]
    assert set(override) <= set(CSERVICES) and not set(override) & set(PICKPLACE_SERVICES)
    for name, svc in override.items():
        assert set(svc) <= {"image", "profiles"}, name
        assert CSERVICES[name]["image"] in smoke.HUB_IMAGES.values(), name
    assert override["grafana"] == {"profiles": ["grafana"]}  # no Grafana here; the real file keeps it
    for name in ("postgres", "prometheus", "zenoh"):
        assert (REPO / "deploy" / "compose-smoke" / "standins" / f"{name}.Dockerfile").exists()


def test_the_smoke_reads_the_debian_mirror_health_and_targets():
    smoke = smoke_module()
    deb822 = (
        "Types: deb\nURIs: http://mirror.example/debian\nSuites: bookworm bookworm-updates\nComponents: main\n\n"
        "Types: deb\nURIs: http://security.example/debian-security\nSuites: bookworm-security\n"
    )
    assert smoke.debian_mirror([deb822]) == "http://mirror.example/debian"
    assert smoke.debian_mirror(["deb [arch=amd64] http://m.example/debian/ bookworm main"]) == (
        "http://m.example/debian"
    )
    assert (
        smoke.debian_mirror(["deb http://m.example/debian bullseye main"]) == "http://deb.debian.org/debian"
    )
    ps = smoke.compose_ps(
        '{"Service":"vision","State":"running","Health":"healthy"}\n'
        '{"Service":"db-migrate","State":"exited","Health":"","ExitCode":0}\n'
        '{"Service":"task","State":"running","Health":"starting"}\n'
    )
    wrong = smoke.unhealthy(ps, {"vision", "db-migrate", "task", "gateway"}, one_shot={"db-migrate"})
    assert wrong == ["gateway: no container", "task: running starting"]
    targets = {
        "data": {
            "activeTargets": [
                {"labels": {"job": "vision"}, "scrapeUrl": "http://vision:9104/metrics", "health": "up"},
                {
                    "labels": {"job": "sim-dobot"},
                    "scrapeUrl": "http://sim-dobot:9100/metrics",
                    "health": "down",
                },
            ]
        }
    }
    n_up, down = smoke.targets_up(targets)
    assert n_up == 1 and down and "sim-dobot" in down[0]
