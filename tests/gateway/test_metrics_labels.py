"""/metrics: one robot_id (the configured one) and the cell id on every series, whoever made it."""

from __future__ import annotations

import pytest
from prometheus_client import CollectorRegistry, Counter

from services.common.bus import Bus
from services.common.metrics import CellMetrics, labelled_registry, render
from tests.gateway.conftest import (
    AUTH,
    fake_task_service,
    gateway_settings,
    migrate_up,
    running_gateway,
    wait_until,
)
from tests.gateway.dashboard_queries import empty_selectors, samples

pytestmark = pytest.mark.integration


def test_every_series_carries_the_cell_and_the_configured_robot() -> None:
    gateway, vision = CellMetrics(), CellMetrics()
    gateway.observe_pick("cell1", "rod", True, 7.5, 0.9)  # a pick event naming its cell, not the robot
    vision.vision_latency.labels("total").observe(0.05)
    own = CollectorRegistry()
    Counter("pickplace_motion_requests", "x", ["rpc", "outcome"], registry=own).labels("Plan", "ok").inc()
    reg = labelled_registry(
        gateway.registry,
        cell_id="cellA",
        robot_id="nova5_a",
        extra=[vision.registry, own],
        with_process_default=False,
    )
    got = samples(render(gateway.registry, reg).decode())
    assert got and all(lab.get("cell_id") == "cellA" and lab.get("robot_id") == "nova5_a" for _, lab in got)
    names = [n for n, _ in got]
    assert "vision_latency_seconds_count" in names and "pickplace_motion_requests_total" in names
    # a family both registries define (every CellMetrics has picks_persisted) is exported once
    assert names.count("picks_persisted_total") == 1


async def test_gateway_metrics_use_the_configured_robot_id(settings, sqlite_db, tmp_path) -> None:  # type: ignore[no-untyped-def]
    await migrate_up(sqlite_db)
    s = gateway_settings(settings, sqlite_db, tmp_path, robot_id="nova5_left")
    s = s.model_copy(update={"cell_id": "bay3"})
    async with (
        Bus(s.zenoh) as bus,
        fake_task_service(bus, s.cell_id, s.grpc.task_port) as task,
        running_gateway(s, bus) as gw,
    ):
        task.cycle_s = 0.05
        r = await gw.client.post("/api/v1/system/start", headers=AUTH, json={"cycles": 2})
        assert r.status_code == 200, r.text
        await wait_until(lambda: gw.cell.writer.written >= 2, 15, "two picks written")
        text = (await gw.client.get("/metrics")).text
    got = samples(text)
    picks = [lab for n, lab in got if n == "pick_success_total"]
    assert picks and all(lab["robot_id"] == "nova5_left" and lab["cell_id"] == "bay3" for lab in picks)
    assert all(lab.get("robot_id") == "nova5_left" and lab.get("cell_id") == "bay3" for _, lab in got)
    # the pick panels find their series for this cell and robot, and none for another cell
    gaps = empty_selectors(text, {"cell": "bay3", "robot": "nova5_left"})
    assert not any(g.startswith(("pick_success_total", "cycle_time_seconds")) for g in gaps), gaps
    other = empty_selectors(text, {"cell": "bay4", "robot": "nova5_left"})
    assert any(g.startswith("pick_success_total") for g in other)  # the check can fail
