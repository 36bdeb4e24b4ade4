"""The REST API over a real loopback socket, on SQLite and PostgreSQL."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from gateway.app import create_app
from gateway.calibration import CalibrationOutcome
from gateway.convert import pick_row
from gateway.db.engine import make_engine, session_factory
from gateway.db.models import Calibration
from gateway.db.repository import insert_picks
from gateway.server import GatewayServer
from services.common.bus import Bus
from services.common.errors import ConfigurationError
from services.common.keys import CellKeys
from services.common.modes import TaskKind
from services.common.settings import DatabaseSettings
from tests.gateway.conftest import (
    AUTH,
    fake_task_service,
    gateway_settings,
    migrate_up,
    pick_event,
    running_gateway,
    wait_until,
)

pytestmark = pytest.mark.integration


async def seed(db: DatabaseSettings, n: int, t0: datetime) -> list[str]:
    """n picks one second apart from t0, every third one failed; returns pick_ids oldest first."""
    events = [
        pick_event(i, success=i % 3 != 0, stamp_ns=int((t0 + timedelta(seconds=i)).timestamp() * 1e9))
        for i in range(n)
    ]
    engine = make_engine(db, db.url)
    try:
        async with session_factory(engine)() as s:
            await insert_picks(s, [pick_row(e, "robot_01") for e in events])
            await s.commit()
    finally:
        await engine.dispose()
    return [e.pick_id for e in events]


async def test_picks_paging_detail_and_404(database, settings, tmp_path):
    await migrate_up(database)
    ids = await seed(database, 45, datetime.now(UTC) - timedelta(minutes=5))
    async with running_gateway(gateway_settings(settings, database, tmp_path)) as gw:
        c = gw.client
        r = await c.get("/api/v1/picks", params={"limit": 20, "offset": 0})
        assert r.status_code == 200 and r.headers["X-Total-Count"] == "45"
        first = r.json()
        assert [p["pick_id"] for p in first] == ids[::-1][:20]  # newest first
        r = await c.get("/api/v1/picks", params={"limit": 20, "offset": 40})
        assert [p["pick_id"] for p in r.json()] == ids[::-1][40:]
        r = await c.get("/api/v1/picks", params={"offset": 45})
        assert r.status_code == 200 and r.json() == []
        r = await c.get("/api/v1/picks", params={"success": "false", "limit": 1000})
        assert r.headers["X-Total-Count"] == "15" and all(not p["success"] for p in r.json())
        assert {p["outcome"] for p in r.json()} == {"failed"}
        assert {p["outcome"] for p in first if p["success"]} == {"succeeded"}

        detail = (await c.get(f"/api/v1/picks/{first[0]['id']}")).json()
        assert detail["pick_id"] == ids[-1] and detail["pick_pose"]["qw"] == 1.0
        assert detail["stage_durations"]["PLAN"] == 0.6
        assert detail["timestamp"].endswith(("Z", "+00:00"))

        r = await c.get("/api/v1/picks/999999")
        assert r.status_code == 404 and r.json() == {"error": "NotFound", "detail": "pick 999999 not found"}
        for bad in ({"limit": 0}, {"limit": 1001}, {"offset": -1}, {"limit": "ten"}):
            r = await c.get("/api/v1/picks", params=bad)
            assert r.status_code == 422, bad
            field = next(iter(bad))
            assert r.json()["errors"][0]["field"] == f"query.{field}"
        assert (await c.get("/api/v1/picks/abc")).status_code == 422

        m = (await c.get("/api/v1/metrics")).json()
        assert m["picks_total"] == 45 and m["picks_failed"] == 15
        assert m["success_rate"] == pytest.approx(30 / 45)
        assert m["cycle_time_p50"] is not None and m["uptime"] > 0
        st = (await c.get("/api/v1/system/status")).json()
        assert st["database"] == "ok" and st["picks_today"] in (
            45,
            0,
        )  # 0 only if the test ran over midnight UTC
        assert st["state"] == "OFFLINE"  # no robot driver, no task service in this test


async def test_mutations_need_the_token_and_nothing_moves(robot_settings, sim_server, sqlite_db, tmp_path):
    from services.robot.service import RobotService

    await migrate_up(sqlite_db)
    s = gateway_settings(robot_settings, sqlite_db, tmp_path)
    async with Bus(s.zenoh) as bus, RobotService(s, bus, grpc_port=0) as robot:
        s = s.model_copy(update={"grpc": s.grpc.model_copy(update={"robot_port": robot.grpc_port})})
        async with fake_task_service(bus, s.cell_id, s.grpc.task_port) as task, running_gateway(s, bus) as gw:
            c = gw.client
            before = (await c.get("/api/v1/config")).json()
            calls = [
                ("POST", "/api/v1/system/start", None),
                ("POST", "/api/v1/system/stop", None),
                ("POST", "/api/v1/system/estop", None),
                ("POST", "/api/v1/system/estop/release", None),
                ("PUT", "/api/v1/config", {"robot": {"speed_ratio": 10}}),
                ("POST", "/api/v1/calibration/handshake", {"num_poses": 5}),
            ]
            for headers in (
                {},
                {"Authorization": "Bearer wrong-token-xxxxxxxxxxxx"},
                {"Authorization": "Basic x"},
            ):
                for method, path, body in calls:
                    r = await c.request(method, path, json=body, headers=headers)
                    assert r.status_code == 401, (method, path, headers, r.text)
                    assert r.headers["WWW-Authenticate"] == "Bearer"
                    assert r.json()["error"] == "Unauthorized"
            assert task.starts == [] and task.stops == 0 and task.estops == 0
            assert not sim_server.controller.estop
            assert (await c.get("/api/v1/config")).json() == before
            # reads stay open
            for path in (
                "/api/v1/system/status",
                "/api/v1/picks",
                "/api/v1/metrics",
                "/metrics",
                "/openapi.json",
            ):
                assert (await c.get(path)).status_code == 200, path


async def test_start_stop_relay_and_503_without_task_service(settings, sqlite_db, tmp_path):
    await migrate_up(sqlite_db)
    s = gateway_settings(settings, sqlite_db, tmp_path, rpc_timeout_s=1.0)
    async with running_gateway(s) as gw:
        r = await gw.client.post("/api/v1/system/start", headers=AUTH)
        assert r.status_code == 503
        body = r.json()
        assert body["error"] == "RobotCommunicationError"
        assert f"task service unreachable at 127.0.0.1:{s.grpc.task_port}" in body["detail"]
        async with fake_task_service(None, s.cell_id, s.grpc.task_port) as task:
            r = await gw.client.post(
                "/api/v1/system/start", headers=AUTH, json={"task": "sort-cubes", "cycles": 3}
            )
            assert r.status_code == 200 and r.json() == {"success": True, "message": "started sort-cubes"}
            r = await gw.client.post("/api/v1/system/start", headers=AUTH, json={"task": "juggle"})
            assert r.status_code == 422 and r.json()["errors"][0]["field"] == "body.task"
            r = await gw.client.post("/api/v1/system/start", headers=AUTH, json={"cycles": -1})
            assert r.status_code == 422 and r.json()["errors"][0]["field"] == "body.cycles"
            r = await gw.client.post("/api/v1/system/stop", headers=AUTH)
            assert r.status_code == 200 and r.json()["success"]
        assert task.starts == [(TaskKind.SORT_CUBES, 3)] and task.stops == 1


async def test_estop_reaches_the_simulated_dobot(robot_settings, sim_server, sqlite_db, tmp_path):
    from services.robot.service import RobotService

    await migrate_up(sqlite_db)
    s = gateway_settings(robot_settings, sqlite_db, tmp_path)
    async with Bus(s.zenoh) as bus, RobotService(s, bus, grpc_port=0) as robot:
        await robot.driver.enable()
        s = s.model_copy(update={"grpc": s.grpc.model_copy(update={"robot_port": robot.grpc_port})})
        async with fake_task_service(bus, s.cell_id, s.grpc.task_port) as task, running_gateway(s, bus) as gw:
            r = await gw.client.post("/api/v1/system/estop", headers=AUTH)
            assert r.status_code == 200, r.text
            assert r.json()["success"] and r.json()["latency_ms"] > 0
            assert sim_server.controller.estop  # pressed before the response came back
            await task.estop_event.wait()
            await wait_until(
                lambda: (gw.cell.hub.robot_status or {}).get("estop_active") is True,
                5.0,
                "the gateway to see the e-stop",
            )
            st = (await gw.client.get("/api/v1/system/status")).json()
            assert st["state"] == "ESTOP" and st["robot"]["estop_active"] and 116 in st["robot"]["alarms"]
            prom = (await gw.client.get("/metrics")).text
            assert 'emergency_stop_total{cell_id="cell1",robot_id="robot_01",source="rest"} 1.0' in prom

            r = await gw.client.post("/api/v1/system/estop/release", headers=AUTH)
            assert r.status_code == 200, r.text
            assert not sim_server.controller.estop
            st = (await gw.client.get("/api/v1/system/status")).json()
            assert st["robot"]["estop_active"] is False and st["robot"]["enabled"] is True


async def test_estop_works_without_the_task_service(robot_settings, sim_server, sqlite_db, tmp_path):
    from services.robot.service import RobotService

    await migrate_up(sqlite_db)
    s = gateway_settings(robot_settings, sqlite_db, tmp_path)
    async with RobotService(s, None, grpc_port=0) as robot:
        s = s.model_copy(update={"grpc": s.grpc.model_copy(update={"robot_port": robot.grpc_port})})
        async with running_gateway(s) as gw:
            r = await gw.client.post("/api/v1/system/estop", headers=AUTH)
            assert r.status_code == 200 and sim_server.controller.estop


async def test_estop_without_robot_driver_is_503_not_success(settings, sqlite_db, tmp_path):
    await migrate_up(sqlite_db)
    async with running_gateway(gateway_settings(settings, sqlite_db, tmp_path)) as gw:
        r = await gw.client.post("/api/v1/system/estop", headers=AUTH)
        assert r.status_code == 503 and "robot driver unreachable" in r.json()["detail"]


async def test_put_config_validates_and_applies(settings, sqlite_db, tmp_path):
    await migrate_up(sqlite_db)
    async with running_gateway(gateway_settings(settings, sqlite_db, tmp_path)) as gw:
        c = gw.client
        cases = [
            ({"robot": {"speed_ratio": 150}}, "body.robot.speed_ratio", "less than or equal to 100"),
            ({"robot": {"speed_ratio": "fast"}}, "body.robot.speed_ratio", "integer"),
            ({"robot": {"speed_ratio": True}}, "body.robot.speed_ratio", "integer"),  # a bool is no number
            (
                {"robot": {"workspace": {"min": [0.5, 0, 0], "max": [0.1, 1, 1]}}},
                "body.robot.workspace",
                "below",
            ),
            ({"robot": {"host": "10.0.0.5"}}, "body.robot", "robot.host cannot be changed"),
            ({"gateway": {"api_token": "x" * 20}}, "body.gateway", "gateway.api_token cannot be changed"),
            ({"motion": {"velocity_scale": 1.5}}, "body.motion.velocity_scale", "less than or equal"),
            ({"nonsense": 1}, "body", "nonsense cannot be changed"),
            ({"robot": {}}, "body.robot", "at least one"),
        ]
        for patch, field, words in cases:
            r = await c.put("/api/v1/config", json=patch, headers=AUTH)
            assert r.status_code == 422, (patch, r.text)
            fields = [e["field"] for e in r.json()["errors"]]
            assert any(f.startswith(field) for f in fields), (patch, fields)
            assert words in r.json()["detail"], (patch, r.json()["detail"])
        r = await c.put(
            "/api/v1/config", content=b"[1, 2]", headers={**AUTH, "Content-Type": "application/json"}
        )
        assert r.status_code == 422
        assert (await c.get("/api/v1/config")).json()["robot"]["speed_ratio"] == settings.robot.speed_ratio

        r = await c.put(
            "/api/v1/config", json={"robot": {"speed_ratio": 25}, "motion": {"planner": "PRM"}}, headers=AUTH
        )
        assert r.status_code == 200 and sorted(r.json()["updated"]) == ["motion.planner", "robot.speed_ratio"]
        # published to the services, which apply these at once (test_config_live shows them do it)
        assert sorted(r.json()["applied_now"]) == ["motion.planner", "robot.speed_ratio"]
        assert r.json()["applied_next_cycle"] == [] and "restart" in r.json()["note"]
        r = await c.put(
            "/api/v1/config",
            json={"gateway": {"joint_state_rate_hz": 5}, "cycle": {"dwell_s": 0.2}},
            headers=AUTH,
        )
        assert r.json()["applied_now"] == ["gateway.joint_state_rate_hz"]
        assert r.json()["applied_next_cycle"] == ["cycle.dwell_s"]
        cfg = (await c.get("/api/v1/config")).json()
        assert cfg["robot"]["speed_ratio"] == 25 and cfg["motion"]["planner"] == "PRM"
        assert cfg["gateway"]["api_token"] == "**********"
        assert "robot.speed_ratio" in cfg["updatable"]


async def test_limits_cors_docs_and_prometheus(settings, sqlite_db, tmp_path):
    await migrate_up(sqlite_db)
    s = gateway_settings(settings, sqlite_db, tmp_path, max_request_bytes=2048)
    async with Bus(s.zenoh) as bus, running_gateway(s, bus) as gw:
        c = gw.client
        r = await c.put("/api/v1/config", content=b"{" + b" " * 5000 + b"}", headers=AUTH)
        assert r.status_code == 413 and "max_request_bytes" in r.json()["detail"]

        async def chunks():  # no Content-Length: counted as it streams
            for _ in range(10):
                yield b" " * 1000

        r = await c.put("/api/v1/config", content=chunks(), headers=AUTH)
        assert r.status_code == 413

        r = await c.options(
            "/api/v1/system/start",
            headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"},
        )
        assert "access-control-allow-origin" not in r.headers
        r = await c.get("/api/v1/picks", headers={"Origin": "http://evil.example"})
        assert "access-control-allow-origin" not in r.headers
        assert r.headers["x-content-type-options"] == "nosniff"

        assert (await c.get("/docs")).status_code == 200
        paths = (await c.get("/openapi.json")).json()["paths"]
        for p in (
            "/api/v1/system/status",
            "/api/v1/system/start",
            "/api/v1/system/stop",
            "/api/v1/system/estop",
            "/api/v1/picks",
            "/api/v1/picks/{pick_id}",
            "/api/v1/metrics",
            "/api/v1/calibration/handshake",
            "/api/v1/config",
        ):
            assert p in paths, p

        keys = CellKeys(s.cell_id)
        bus.publish(keys.pick_events, pick_event(0))
        bus.publish(keys.pick_events, pick_event(1, success=False))
        await wait_until(lambda: gw.cell.writer.written == 2, 5.0, "two picks written")
        prom = (await c.get("/metrics")).text
        cr = 'cell_id="cell1",'
        assert f'pick_success_total{{{cr}object_class="rod",robot_id="robot_01"}} 1.0' in prom
        assert (
            f'pick_failure_total{{{cr}object_class="cube_red",robot_id="robot_01",stage="GRASP"}} 1.0' in prom
        )
        assert f'cycle_time_seconds_count{{{cr}robot_id="robot_01"}} 1.0' in prom
        assert f'grasp_quality{{{cr}robot_id="robot_01"}}' in prom
        assert f'picks_persisted_total{{{cr}robot_id="robot_01"}} 2.0' in prom


async def test_calibration_run_progress_and_record(settings, sqlite_db, tmp_path):
    import asyncio

    await migrate_up(sqlite_db)
    release = asyncio.Event()

    async def executor(num_poses, progress):  # type: ignore[no-untyped-def]
        for i in range(num_poses):
            progress((i + 1) / num_poses, f"pose {i + 1}/{num_poses}")
            if i == 1:
                await release.wait()
        return CalibrationOutcome(
            {"T_base_camera": [[1, 0, 0, 0.9], [0, 1, 0, 0], [0, 0, 1, 0.6], [0, 0, 0, 1]]},
            0.42,
            "14 of 15 views used",
        )

    s = gateway_settings(settings, sqlite_db, tmp_path)
    async with running_gateway(s, calibration_executor=executor) as gw:
        c = gw.client
        r = await c.post("/api/v1/calibration/handshake", json={"num_poses": 4}, headers=AUTH)
        assert r.status_code == 202
        cid = r.json()["calibration_id"]
        view = (await c.get(f"/api/v1/calibration/{cid}")).json()
        assert view["status"] == "running" and view["progress"] == 0.5 and view["message"] == "pose 2/4"
        r = await c.post("/api/v1/calibration/handshake", json={"num_poses": 4}, headers=AUTH)
        assert r.status_code == 409 and cid in r.json()["detail"]
        r = await c.post("/api/v1/calibration/handshake", json={"num_poses": 2}, headers=AUTH)
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "body.num_poses"
        release.set()
        await wait_until(
            lambda: gw.cell.calibration.runs[cid].status == "succeeded", 5.0, "the run to finish"
        )
        view = (await c.get(f"/api/v1/calibration/{cid}")).json()
        assert view["status"] == "succeeded" and view["reprojection_error"] == 0.42
        assert view["parameters"]["T_base_camera"][0][3] == 0.9
        assert (await c.get("/api/v1/calibration/0123abcd")).status_code == 404
    engine = make_engine(sqlite_db, sqlite_db.url)
    async with session_factory(engine)() as sess:
        row = await sess.get(Calibration, 1)
    await engine.dispose()
    assert (
        row is not None and row.run_id == cid and row.status == "succeeded" and row.reprojection_error == 0.42
    )


async def test_calibration_without_routine_is_409(settings, sqlite_db, tmp_path):
    await migrate_up(sqlite_db)
    async with running_gateway(gateway_settings(settings, sqlite_db, tmp_path)) as gw:
        r = await gw.client.post("/api/v1/calibration/handshake", headers=AUTH)
        assert r.status_code == 409 and "calibration routine" in r.json()["detail"]


async def test_refuses_unmigrated_database_and_missing_token(settings, sqlite_db, tmp_path):
    s = gateway_settings(settings, sqlite_db, tmp_path)
    with pytest.raises(ConfigurationError, match=r"never migrated.*pickplace db upgrade"):
        async with GatewayServer(create_app(s)):
            pass
    no_token = s.model_copy(update={"gateway": s.gateway.model_copy(update={"api_token": None})})
    with pytest.raises(ConfigurationError, match="PICKPLACE_GATEWAY__API_TOKEN"):
        create_app(no_token)
    # the embedded run migrates by itself
    auto = s.model_copy(update={"database": s.database.model_copy(update={"auto_migrate": True})})
    async with running_gateway(auto) as gw:
        assert (await gw.client.get("/api/v1/picks")).status_code == 200


async def test_system_health_is_sampled_and_stored(settings, database, tmp_path):
    from sqlalchemy import func, select

    from gateway.db.models import SystemHealth

    await migrate_up(database)
    async with running_gateway(gateway_settings(settings, database, tmp_path, health_period_s=0.1)) as gw:
        await wait_until(lambda: gw.cell.health is not None, 5.0, "a health sample")
        health = (await gw.client.get("/api/v1/system/status")).json()["health"]
        assert 0 < health["memory_percent"] <= 100 and 0 < health["disk_percent"] <= 100

        async def stored() -> bool:
            async with gw.cell.sessions() as s:
                return bool(await s.scalar(select(func.count()).select_from(SystemHealth)))

        await wait_until(stored, 5.0, "a system_health row")


async def test_embedded_gateway_generates_a_token_and_migrates(settings, sqlite_db, tmp_path):
    import httpx

    from gateway.server import embedded_gateway

    s = gateway_settings(settings, sqlite_db, tmp_path, port=0)
    s = s.model_copy(update={"gateway": s.gateway.model_copy(update={"api_token": None})})
    async with Bus(s.zenoh) as bus, embedded_gateway(s, bus) as (server, url):
        assert url.startswith(f"http://127.0.0.1:{server.port}/#token=")
        token = url.split("#token=", 1)[1]
        assert len(token) >= 40
        async with httpx.AsyncClient(base_url=server.url) as c:
            assert (await c.get("/api/v1/picks")).status_code == 200  # migrated by itself
            r = await c.put(
                "/api/v1/config",
                json={"robot": {"speed_ratio": 40}},
                headers={"Authorization": f"Bearer {token}"},
            )
            assert r.status_code == 200
            assert (await c.put("/api/v1/config", json={"robot": {"speed_ratio": 41}})).status_code == 401


async def test_a_cycle_cut_by_a_crash_is_listed_as_interrupted(database, settings, tmp_path):
    from pickplace.v1 import task_pb2

    await migrate_up(database)
    started = pick_event(0, success=False)
    started.status = task_pb2.PICK_STATUS_RUNNING
    started.stage_reached = "REORIENT"
    cut = task_pb2.PickEvent()
    cut.CopyFrom(started)
    cut.status = task_pb2.PICK_STATUS_INTERRUPTED
    cut.failure_reason, cut.error_code = (
        "REORIENT: interrupted: the task process ended",
        "CycleInterruptedError",
    )
    engine = make_engine(database, database.url)
    try:
        for ev in (started, cut):
            async with session_factory(engine)() as s:
                await insert_picks(s, [pick_row(ev, "robot_01")])
                await s.commit()
    finally:
        await engine.dispose()
    async with running_gateway(gateway_settings(settings, database, tmp_path)) as gw:
        (row,) = (await gw.client.get("/api/v1/picks")).json()
        assert (row["pick_id"], row["outcome"], row["success"]) == (cut.pick_id, "interrupted", False)
        assert row["stage_reached"] == "REORIENT"
        detail = (await gw.client.get(f"/api/v1/picks/{row['id']}")).json()
        assert detail["outcome"] == "interrupted"
