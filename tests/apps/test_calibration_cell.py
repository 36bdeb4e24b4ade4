"""POST /calibration/handshake on the embedded cell (as `pickplace up` serves it): a real eye-to-hand
run in the twin with the board on the flange, progress by GET, the true camera pose recovered."""

from __future__ import annotations

import asyncio

import httpx
import numpy as np
import pytest

from gateway.server import embedded_gateway
from services.apps.cell import Cell
from services.apps.up import _calibration_executor
from services.sim.twin.calibration_board import twin_calibration_settings
from services.sim.twin.ground_truth import T_base_camera
from tests.apps.conftest import cell_settings

pytestmark = [pytest.mark.integration, pytest.mark.slow]


async def test_calibration_handshake_recovers_the_twin_camera(tmp_path):
    base = cell_settings(
        tmp_path,
        gateway={"port": 0},
        sim={"speed": 3.0},
        database={"url": f"sqlite+aiosqlite:///{tmp_path / 'cal.db'}"},
    )
    s = twin_calibration_settings(base)
    async with (
        Cell(s, seed=0) as cell,
        embedded_gateway(cell.settings, cell.bus, _calibration_executor(cell)) as (server, url),
        httpx.AsyncClient(base_url=server.url, timeout=30.0) as http,
    ):
        token = url.split("#token=", 1)[1]
        auth = {"Authorization": f"Bearer {token}"}
        r = await http.post("/api/v1/calibration/handshake", json={"num_poses": 8})
        assert r.status_code == 401  # no token, nothing moves
        r = await http.post("/api/v1/calibration/handshake", json={"num_poses": 8}, headers=auth)
        assert r.status_code == 202, r.text
        run_id = r.json()["calibration_id"]
        status = {}
        for _ in range(600):  # bounded: at most ~120 s
            status = (await http.get(f"/api/v1/calibration/{run_id}")).json()
            if status["status"] != "running":
                break
            await asyncio.sleep(0.2)
    assert status["status"] == "succeeded", status
    assert status["progress"] == 1.0 and status["parameters"]["poses_used"] >= 6
    T = np.asarray(status["parameters"]["T_base_camera"])
    T_true = T_base_camera(s.sim.twin.camera)
    assert np.linalg.norm(T[:3, 3] - T_true[:3, 3]) < 0.002
    cos = (np.trace(T[:3, :3].T @ T_true[:3, :3]) - 1) / 2
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))) < 0.5
