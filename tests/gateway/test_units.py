"""Pure parts of the gateway: config patches, tokens, event validation, the live hub, metrics, health."""

from __future__ import annotations

import itertools
import json
import math

import pytest
from pickplace.v1 import common_pb2, robot_pb2
from prometheus_client import generate_latest

from gateway import health
from gateway.convert import pick_row, validate_pick_event
from gateway.errors import status_for
from gateway.live import CLIENT_QUEUE, LiveHub
from gateway.security import bearer_from_header, generate_token, token_matches
from services.common import errors as E
from services.common.config_patch import ConfigRejected, apply_patch, is_updatable, leaf_paths
from services.common.metrics import CellMetrics
from services.common.settings import GatewaySettings, load_settings
from tests.gateway.conftest import pick_event


@pytest.fixture(scope="module")
def base_settings():  # type: ignore[no-untyped-def]
    return load_settings("sim", overrides={"logging": {"file": None}})


# ---------------------------------------------------------------------------- config patches
def test_patch_applies_valid_values_only(base_settings):
    new, changed = apply_patch(
        base_settings, {"robot": {"speed_ratio": 20, "workspace": {"max": [0.8, 0.8, 1.0]}}}
    )
    assert new.robot.speed_ratio == 20 and new.robot.workspace.max == (0.8, 0.8, 1.0)
    assert new.robot.workspace.min == base_settings.robot.workspace.min  # merged, not replaced
    assert sorted(changed) == ["robot.speed_ratio", "robot.workspace.max"]
    assert base_settings.robot.speed_ratio == 50  # the original is untouched


def test_patch_replaces_drop_zones_whole(base_settings):
    zones = {"red": (0.3, 0.4), "blue": (0.4, 0.4), "green": (0.3, -0.4), "black": (0.4, -0.4)}
    new, changed = apply_patch(base_settings, {"sim": {"twin": {"scene": {"drop_zones_m": zones}}}})
    assert new.sim.twin.scene.drop_zones_m == zones and changed == ["sim.twin.scene.drop_zones_m"]
    with pytest.raises(ConfigRejected, match="drop zone"):
        apply_patch(base_settings, {"sim": {"twin": {"scene": {"drop_zones_m": {"red": (0.3, 0.4)}}}}})


@pytest.mark.parametrize(
    ("patch", "field"),
    [
        ({"robot": {"speed_ratio": 0}}, "robot.speed_ratio"),
        ({"robot": {"acc_ratio": 101}}, "robot.acc_ratio"),
        ({"robot": {"host": "203.0.113.9"}}, "robot.host"),  # a non-loopback address is refused
        ({"robot": {"workspace": {"min": [1, 1, 1]}}}, "robot.workspace"),
        ({"gateway": {"joint_state_rate_hz": 0}}, "gateway.joint_state_rate_hz"),
        ({"vision": {"rate_hz": float("nan")}}, "vision.rate_hz"),
        ({"zenoh": {"multicast_scouting": True}}, "zenoh.multicast_scouting"),
    ],
)
def test_patch_rejections_name_the_field(base_settings, patch, field):
    with pytest.raises(ConfigRejected) as err:
        apply_patch(base_settings, patch)
    assert any(e["field"].startswith(field) for e in err.value.errors), err.value.errors
    assert isinstance(err.value, E.InvalidInputError) and status_for(err.value) == 422


@pytest.mark.parametrize("patch", [{}, [], "robot", None, 3])
def test_patch_must_be_an_object(base_settings, patch):
    with pytest.raises(ConfigRejected, match="non-empty JSON object"):
        apply_patch(base_settings, patch)


def test_leaf_paths_and_allow_list():
    assert sorted(leaf_paths({"a": {"b": 1, "c": {"d": 2}}, "e": []})) == ["a.b", "a.c.d", "e"]
    assert is_updatable("robot.workspace.min") and not is_updatable("robot.workspace_extra")
    assert not is_updatable("robot") and not is_updatable("gateway.api_token")


# ---------------------------------------------------------------------------- tokens and settings
def test_tokens():
    t = generate_token()
    assert len(t) >= 40 and t != generate_token()
    assert token_matches(t, t) and not token_matches(t[:-1], t) and not token_matches(None, t)
    assert bearer_from_header(f"Bearer {t}") == t and bearer_from_header(f"bearer  {t} ") == t
    assert bearer_from_header("Basic abc") is None and bearer_from_header("Bearer ") is None
    assert bearer_from_header(None) is None


def test_gateway_settings_are_safe_by_default():
    gw = GatewaySettings()
    assert gw.host == "127.0.0.1" and gw.api_token is None and gw.cors_origins == []
    with pytest.raises(ValueError, match="at least 16"):
        GatewaySettings(api_token="short")
    with pytest.raises(ValueError, match="not loopback"):
        GatewaySettings(host="0.0.0.0")
    assert GatewaySettings(host="0.0.0.0", allow_remote=True).host == "0.0.0.0"
    with pytest.raises(ValueError, match="'\\*' is refused"):
        GatewaySettings(cors_origins=["*"])


def test_token_and_database_from_environment(monkeypatch):
    monkeypatch.setenv("PICKPLACE_GATEWAY__API_TOKEN", "env-token-0123456789")
    monkeypatch.setenv("PICKPLACE_DATABASE__URL", "postgresql+asyncpg://u@127.0.0.1:5432/cell")
    s = load_settings("sim", overrides={"logging": {"file": None}})
    assert (
        s.gateway.api_token is not None and s.gateway.api_token.get_secret_value() == "env-token-0123456789"
    )
    assert "env-token" not in repr(s.gateway)  # never printed
    assert s.database.url.startswith("postgresql+asyncpg://")


# ---------------------------------------------------------------------------- pick events
def test_pick_validation_names_the_problem():
    ev = pick_event(1)
    validate_pick_event(ev)
    bad = pick_event(1)
    bad.pick_id = ""
    with pytest.raises(E.InvalidInputError, match="empty pick_id"):
        validate_pick_event(bad)
    bad = pick_event(1)
    bad.pick_pose.x = math.nan
    with pytest.raises(E.InvalidInputError, match="pick_pose has non-finite"):
        validate_pick_event(bad)
    bad = pick_event(1)
    bad.cycle_time_s = -1
    with pytest.raises(E.InvalidInputError, match="cycle_time_s"):
        validate_pick_event(bad)
    bad = pick_event(1)
    bad.pick_id = "x" * 65
    with pytest.raises(E.InvalidInputError, match="longer than 64"):
        validate_pick_event(bad)


def test_pick_row_clips_and_defaults():
    ev = pick_event(2)
    ev.robot_id = ""
    ev.object_class = "c" * 80
    ev.ClearField("place_pose")
    row = pick_row(ev, "robot_07")
    assert row["robot_id"] == "robot_07" and len(row["object_class"]) == 50
    assert row["place_pose"] is None and row["pick_pose"]["x"] == 0.45
    assert row["timestamp"].tzinfo is not None


# ---------------------------------------------------------------------------- live hub
def _js(stamp_ns: int) -> common_pb2.JointState:
    return common_pb2.JointState(header=common_pb2.Header(stamp_ns=stamp_ns), name=["joint1"], position=[0.1])


def test_hub_decimates_joint_states():
    hub = LiveHub(joint_rate_hz=20)
    forwarded = [hub.on_joint_state(_js(k * 8_000_000)) for k in range(1, 251)]  # 2 s at 125 Hz
    assert sum(forwarded) in (40, 41)  # 20 Hz, plus the first sample
    sent = [k * 8 for k, f in zip(range(1, 251), forwarded, strict=True) if f]
    assert max(b - a for a, b in itertools.pairwise(sent)) <= 56  # never more than a slot + a packet
    # after a pause the schedule restarts at once rather than bursting to catch up
    assert hub.on_joint_state(_js(10_000_000_000)) is True
    assert hub.on_joint_state(_js(10_008_000_000)) is False


def test_hub_decimates_on_the_controller_clock_when_the_state_carries_it():
    # receive stamps bunched by a busy machine (1 ms apart) but controller stamps 8 ms apart: the
    # controller's clock decides, so 20 Hz of controller time comes out
    hub = LiveHub(joint_rate_hz=20)
    forwarded = []
    for k in range(1, 251):
        msg = _js(1_000_000_000 + k * 1_000_000)
        msg.source_stamp_ns = k * 8_000_000
        forwarded.append(hub.on_joint_state(msg))
    assert sum(forwarded) in (40, 41)
    last = max(k for k, f in zip(range(1, 251), forwarded, strict=True) if f)
    assert hub.joint_state is not None and hub.joint_state["source_stamp_ns"] == last * 8_000_000


def test_hub_ignores_a_status_answer_older_than_the_shown_one():
    hub = LiveHub()
    estopped = robot_pb2.RobotStatus(connected=True, estop_active=True, robot_mode=9)
    running = robot_pb2.RobotStatus(connected=True, robot_mode=7)
    hub.on_robot_status(estopped, asked_at=10.0)
    hub.on_robot_status(running, asked_at=9.5)  # a poll sent before the e-stop, answered after it
    assert hub.robot_status is not None and hub.robot_status["estop_active"] is True
    hub.on_robot_status(running, asked_at=10.5)
    assert hub.robot_status["estop_active"] is False


def test_hub_slow_client_keeps_newest():
    hub = LiveHub(joint_rate_hz=1000)
    with hub.connection() as q:
        for k in range(1, CLIENT_QUEUE + 20):
            hub.on_joint_state(_js(k * 10_000_000))
        assert q.qsize() == CLIENT_QUEUE
        items = [json.loads(q.get_nowait()) for _ in range(q.qsize())]
    assert items[-1]["data"]["stamp_ns"] == (CLIENT_QUEUE + 19) * 10_000_000
    assert hub.connections == 0


# ---------------------------------------------------------------------------- metrics and health
def test_metrics_registries_are_independent_and_named_by_convention():
    a, b = CellMetrics(), CellMetrics()
    a.observe_pick("r1", "rod", True, 7.5, 0.9)
    a.observe_pick("r1", "rod", False, 0.0, None, stage="GRASP")
    a.set_joint_positions("r1", ["joint1"], [0.5])
    text = generate_latest(a.registry).decode()
    assert 'pick_success_total{object_class="rod",robot_id="r1"} 1.0' in text
    assert 'pick_failure_total{object_class="rod",robot_id="r1",stage="GRASP"} 1.0' in text
    assert 'cycle_time_seconds_sum{robot_id="r1"} 7.5' in text
    assert 'grasp_quality{robot_id="r1"} 0.9' in text
    assert 'robot_joint_position_radians{joint="joint1",robot_id="r1"} 0.5' in text
    for name in ("vision_latency_seconds", "planning_latency_seconds", "robot_mode", "emergency_stop_total"):
        assert f"# TYPE {name.removesuffix('_total')}" in text
    assert "pick_success_total{" not in generate_latest(b.registry).decode()


def test_health_sample_has_the_columns(tmp_path):
    s = health.sample(tmp_path, with_gpu=False)
    assert set(s) == {
        "cpu_percent",
        "memory_percent",
        "disk_percent",
        "gpu_percent",
        "gpu_memory_mb",
        "temperature_celsius",
    }
    assert 0 <= s["memory_percent"] <= 100 and 0 <= s["disk_percent"] <= 100
    assert s["gpu_percent"] is None


def test_error_status_mapping():
    assert status_for(E.RobotCommunicationError("x")) == 503
    assert status_for(E.EmergencyStopError("x")) == 409
    assert status_for(E.InvalidInputError("x")) == 422
    assert status_for(E.IKFailureError("x")) == 409
    assert status_for(E.RobotError("x")) == 500


async def test_read_cache_expires_and_clears():
    from gateway.cache import ReadCache

    now = [0.0]
    cache = ReadCache(ttl_s=2.0, clock=lambda: now[0])
    calls = []

    async def compute() -> int:
        calls.append(now[0])
        return len(calls)

    assert await cache.get("k", compute) == 1
    now[0] = 1.9
    assert await cache.get("k", compute) == 1  # fresh
    now[0] = 2.0
    assert await cache.get("k", compute) == 2  # expired
    cache.clear()
    assert await cache.get("k", compute) == 3
    assert await cache.get("other", compute) == 4
    assert (cache.hits, cache.misses) == (1, 4)


async def test_a_value_read_while_the_cache_was_cleared_is_not_kept():
    """A summary read that began before a write and ended after the writer cleared the cache is answered
    but not kept: the next read computes again and sees the write (a cached stale "no picks" failed the
    operator panel's test on a loaded machine)."""
    import asyncio

    from gateway.cache import ReadCache

    cache = ReadCache(ttl_s=2.0, clock=lambda: 0.0)  # never expires by time
    stored = [0]  # picks in the "database"
    reading, written = asyncio.Event(), asyncio.Event()

    async def slow_summary() -> int:
        seen = stored[0]  # the query reads before the write commits ...
        reading.set()
        await written.wait()  # ... and answers after the writer cleared the cache
        return seen

    async def quick_summary() -> int:
        return stored[0]

    read = asyncio.create_task(cache.get("summary", slow_summary))
    await reading.wait()
    stored[0] = 1
    cache.clear()  # the pick writer, once the pick is stored
    written.set()
    assert await read == 0  # answered as it was read
    assert await cache.get("summary", quick_summary) == 1  # not kept: read again
    assert await cache.get("summary", slow_summary) == 1  # and this one is kept
    assert (cache.hits, cache.misses) == (1, 2)


def test_metrics_multiprocess_mode_aggregates_every_process(tmp_path):
    """With PROMETHEUS_MULTIPROC_DIR set, each service process writes its values there and one /metrics
    shows them all (the env var must be set before prometheus_client is imported: subprocesses)."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "PROMETHEUS_MULTIPROC_DIR": str(tmp_path)}
    write = (
        "from services.common.metrics import CellMetrics\n"
        "m = CellMetrics()\n"
        "m.observe_pick('robot_01', 'rod', True, 8.0, 0.7)\n"
    )
    for _ in range(2):  # two "services"
        subprocess.run([sys.executable, "-c", write], env=env, check=True, timeout=60)
    read = (
        "from services.common.metrics import CellMetrics, render\n"
        "print(render(CellMetrics().registry).decode())\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", read], env=env, check=True, timeout=60, capture_output=True, text=True
    ).stdout
    assert 'pick_success_total{object_class="rod",robot_id="robot_01"} 2.0' in out
    assert 'cycle_time_seconds_count{robot_id="robot_01"} 2.0' in out


def test_hub_keeps_the_current_cycles_plans_and_starts_afresh_with_the_next():
    from pickplace.v1 import common_pb2, task_pb2

    from gateway.live import PLANS_KEPT

    def plan(cycle: int, seq: int) -> task_pb2.TaskPlan:
        p = task_pb2.TaskPlan(cycle_index=cycle, label=f"move{seq}")
        p.header.seq = seq
        p.tool_path.extend([common_pb2.Point(x=0.4, y=0.0, z=0.1 * k) for k in range(3)])
        return p

    hub = LiveHub()
    changes: list[str] = []
    hub.on_change = changes.append
    with hub.connection() as q:
        assert json.loads(q.get_nowait())["type"] == "timeline"
        hub.on_plan(plan(1, 1))
        hub.on_plan(plan(1, 2))
        sent = json.loads(q.get_nowait()), json.loads(q.get_nowait())
    assert [m["type"] for m in sent] == ["plan", "plan"]
    assert [p["label"] for p in sent[-1]["data"]["plans"]] == ["move1", "move2"]
    assert sent[-1]["data"]["plans"][0]["path"][2] == [0.4, 0.0, 0.2]
    assert changes == []  # a plan does not touch the status snapshot
    hub.on_plan(plan(2, 3))
    assert hub.plan is not None and hub.plan["cycle_index"] == 2 and len(hub.plan["plans"]) == 1
    for k in range(PLANS_KEPT + 5):
        hub.on_plan(plan(2, 10 + k))
    assert len(hub.plan["plans"]) == PLANS_KEPT and hub.plan["plans"][-1]["seq"] == 10 + PLANS_KEPT + 4
    assert {"type": "plan", "data": hub.plan} in hub.snapshot()  # a dashboard connecting later sees them


def test_hub_timeline_keeps_what_happened_for_a_dashboard_that_connects_later():
    from pickplace.v1 import task_pb2

    hub = LiveHub()
    for state in ("DETECT", "DETECT", "PLAN", "PLAN", "ESTOP"):  # the task reports at 2 Hz
        hub.on_task_status(task_pb2.TaskStatus(state=state))
    hub.on_robot_status(robot_pb2.RobotStatus(connected=True, estop_active=True, alarms=[116]), asked_at=1.0)
    hub.on_event("estop", {"message": "e-stop pressed"})
    hub.on_picks([{"id": 1, "success": True}, {"id": 2, "success": False, "error_code": "GraspFailureError"}])
    hub.on_joint_state(_js(10_000_000))  # not an event
    with hub.connection() as q:
        first = json.loads(q.get_nowait())
    assert first["type"] == "timeline"
    kinds = [
        (m["type"], m["data"].get("state") if m["type"] == "task_status" else None) for m in first["data"]
    ]
    assert kinds == [
        ("task_status", "DETECT"),
        ("task_status", "PLAN"),
        ("task_status", "ESTOP"),
        ("robot_status", None),
        ("estop", None),
        ("picks", None),
    ]
    assert [p["id"] for p in first["data"][-1]["data"]] == [2]  # the failed pick only
    stamps = [m["at_ms"] for m in first["data"]]
    assert stamps == sorted(stamps) and stamps[0] > 1.7e12  # wall time in ms, in order
