"""The deployed topology for real: every service its own OS process on loopback, started with the
commands and environment names of docker-compose.yml, PostgreSQL as the database. One pick-and-stand,
then the vision process is killed mid-cycle; the launcher restarts it, the next cycle succeeds and
every pick reached the database. The live ``/metrics`` pages are checked against the dashboards."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import urllib.request
from typing import Any

import pytest
from pickplace.v1 import task_pb2

from services.apps.cycles import enable_robot, park_arm, run_single_cycle
from services.apps.launcher import Launcher
from services.apps.topology import SERVICES, LocalPorts, topology
from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.modes import TaskKind
from services.common.settings import load_settings
from services.sim.bus_link import request_scene_reset
from tests.deploy.promtext import (
    dashboards,
    exposition_names,
    exposition_samples,
    queried_metrics,
    query_exprs,
)
from tests.gateway.conftest import PG_URL, postgres_schema

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.postgres, pytest.mark.timeout(420)]

TOKEN = "deploy-test-token-0123456789"
AFTER_DETECT = {"GRASP", "LIFT", "REORIENT", "PLACE", "RELEASE"}


def http_get(url: str) -> str:
    with urllib.request.urlopen(url, timeout=5) as r:
        return r.read().decode()


async def wait_for_state(sub, states: set[str], timeout_s: float) -> str:  # type: ignore[no-untyped-def]
    async with asyncio.timeout(timeout_s):
        while True:
            st = await sub.get()
            if st.state in states:
                return st.state


async def stored_picks(
    schema: str, pick_ids: list[str], timeout_s: float = 15.0
) -> dict[str, tuple[Any, ...]]:
    import asyncpg

    conn = await asyncpg.connect(PG_URL.replace("postgresql+asyncpg://", "postgresql://"), timeout=5)
    try:
        async with asyncio.timeout(timeout_s):
            while True:
                rows = await conn.fetch(
                    f'SELECT pick_id, success, outcome, stage_reached, error_message FROM "{schema}".picks '
                    "WHERE pick_id = ANY($1)",
                    pick_ids,
                )
                if len(rows) == len(pick_ids) and all(r["outcome"] != "running" for r in rows):
                    return {r["pick_id"]: tuple(r)[1:] for r in rows}
                await asyncio.sleep(0.3)
    except TimeoutError:
        return {r["pick_id"]: tuple(r)[1:] for r in rows}
    finally:
        await conn.close()


async def test_processes_pick_survive_a_vision_crash_and_keep_every_pick(tmp_path):
    async with postgres_schema() as schema:
        s = load_settings(
            "sim",
            overrides={
                "database": {"url": PG_URL, "schema_name": schema},
                "sim": {"seed": 3},
                "logging": {"file": str(tmp_path / "test.log")},
                # the token every service asks for: the test's own calls carry it like the launcher's
                "gateway": {"api_token": TOKEN},
            },
        )
        ports = LocalPorts.free()
        specs = topology(
            s,
            ports,
            api_token=TOKEN,
            metrics_root=tmp_path / "metrics",
            log_dir=tmp_path / "log",
            state_dir=tmp_path / "gateway",
        )
        async with Launcher(
            s, specs, ports, log_dir=tmp_path / "log", metrics_root=tmp_path / "metrics", restart_delay_s=0.5
        ) as launcher:
            cs = launcher.settings
            pids = {name: child.pid for name, child in launcher.children.items()}
            assert set(pids) == set(SERVICES)
            assert len(set(pids.values())) == len(SERVICES) and os.getpid() not in pids.values()
            keys = CellKeys(cs.cell_id)
            async with Bus(cs.zenoh) as watcher:
                events = watcher.subscribe(keys.pick_events, task_pb2.PickEvent)
                statuses = watcher.subscribe(keys.task_status, task_pb2.TaskStatus)
                await asyncio.sleep(0.3)  # let the subscriptions reach the router

                await enable_robot(cs)
                first = await run_single_cycle(cs, TaskKind.STAND_ROD)
                assert first.success, first.failure_reason
                assert first.object_class == "rod"
                assert await request_scene_reset(watcher, cs.cell_id) == 4  # the rod lies on the table again

                # second cycle: kill the vision process once the rod has been seen and the arm works
                while not statuses._queue.empty():
                    statuses._queue.get_nowait()
                second_call = asyncio.create_task(run_single_cycle(cs, TaskKind.STAND_ROD))
                await wait_for_state(statuses, AFTER_DETECT, timeout_s=120)
                vision_pid = launcher.children["vision"].pid
                assert vision_pid is not None
                os.kill(vision_pid, signal.SIGKILL)
                second = await second_call  # success or not, it is a pick record
                await launcher.wait_restarted("vision", 1, timeout_s=120)
                assert launcher.children["vision"].pid != vision_pid
                exits = [e for e in launcher.events if e.service == "vision" and e.kind == "exited"]
                assert len(exits) == 1 and f"code {-signal.SIGKILL}" in exits[0].detail

                if not second.success:  # the operator's part: the arm out of the camera's view
                    await park_arm(cs)
                await request_scene_reset(watcher, cs.cell_id)
                third = await run_single_cycle(cs, TaskKind.STAND_ROD)
                assert third.success, third.failure_reason

                ids = [first.pick_id, second.pick_id, third.pick_id]
                published: set[str] = set()
                with contextlib.suppress(TimeoutError):
                    while not set(ids) <= published:  # each cycle's PickEvent went out on Zenoh
                        published.add((await events.get(timeout_s=10.0)).pick_id)
                events.close()
                statuses.close()
                # each outcome stored while the cell runs (one still on its way at a stop would reach the
                # database only at the next start, from the task's journal)
                stored = await stored_picks(schema, ids)

            assert len(set(ids)) == 3
            assert set(ids) <= published
            others = {n: c.restarts for n, c in launcher.children.items() if n != "vision"}
            assert all(r == 0 for r in others.values()), others

            # no pick record lost, outcomes as reported
            success = {pick_id: row[0] for pick_id, row in stored.items()}
            assert success == {first.pick_id: True, second.pick_id: second.success, third.pick_id: True}, (
                stored
            )

            # the live metrics: every series the dashboards query is exported by a running service
            gateway_text = http_get(f"http://127.0.0.1:{ports.gateway}/metrics")
            per_service = {
                spec.name: http_get(f"http://127.0.0.1:{spec.metrics_port}/metrics")
                for spec in specs
                if spec.metrics_port is not None
            }
            live = exposition_names(gateway_text).union(*(exposition_names(t) for t in per_service.values()))
            assert sum(exposition_samples(gateway_text, "pick_success_total")) >= 2
            assert sum(exposition_samples(per_service["vision"], "vision_latency_seconds_count")) > 0
            queried = set().union(
                *(queried_metrics(e) for d in dashboards().values() for e in query_exprs(d))
            )
            assert queried, "the dashboards query no metric"
            assert queried <= live, f"dashboard metrics no service exports: {sorted(queried - live)}"
        # stopped cleanly: every child has exited
        assert all(c.proc is not None and c.proc.returncode is not None for c in launcher.children.values())
