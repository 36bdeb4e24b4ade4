"""The API contract: what the OpenAPI document promises is what the gateway answers.

A seeded schemathesis slice (all checks, all phases, stateful links) runs against a live gateway with
a scripted task service and robot driver; the points the issue found broken are pinned one by one.
``make fuzz-api`` runs the same harness much longer.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import httpx
import pytest

from tests.gateway.conftest import AUTH
from tests.gateway.fuzz_api import FuzzCell, fresh_dir, fuzz_cell, run_schemathesis

pytestmark = pytest.mark.integration


@pytest.fixture
async def cell(tmp_path: Path) -> AsyncIterator[FuzzCell]:
    async with fuzz_cell(tmp_path) as c:
        yield c


async def test_a_seeded_schemathesis_slice_finds_nothing(cell: FuzzCell, tmp_path: Path) -> None:
    report = fresh_dir(str(tmp_path / "report"))
    r = await run_schemathesis(cell.url, seed=7, max_examples=12, report_dir=report)
    assert r.report["requests"] > 300, r.output[-3000:]  # it really ran every phase
    assert r.report["failures"] == [], r.output[-6000:]
    assert r.returncode == 0, r.output[-6000:]
    for phase in ("Coverage", "Fuzzing", "Stateful"):
        assert f"✅  {phase}" in r.output, r.output[-3000:]


async def test_openapi_declares_bearer_auth_and_one_error_model(cell: FuzzCell) -> None:
    async with httpx.AsyncClient(base_url=cell.url) as c:
        doc = (await c.get("/openapi.json")).json()
    assert doc["components"]["securitySchemes"]["bearerAuth"] == {
        "type": "http",
        "scheme": "bearer",
        "description": "gateway.api_token",
    }
    start = doc["paths"]["/api/v1/system/start"]["post"]
    assert start["security"] == [{"bearerAuth": []}]
    assert {"200", "400", "401", "409", "413", "422", "503"} == set(start["responses"])
    assert "HTTPValidationError" not in doc["components"]["schemas"]  # FastAPI's 422, which it never sent
    for path, ops in doc["paths"].items():
        for method, op in ops.items():
            for code, resp in op["responses"].items():
                if code.startswith(("4", "5")):
                    ref = resp["content"]["application/json"]["schema"]["$ref"]
                    assert ref == "#/components/schemas/ErrorBody", (method, path, code)
    urdf = doc["paths"]["/api/v1/robot/urdf"]["get"]["responses"]["200"]["content"]
    assert list(urdf) == ["application/xml"]
    links = doc["paths"]["/api/v1/calibration/handshake"]["post"]["responses"]["202"]["links"]
    assert links["GetCalibration"]["operationId"] == "get_calibration"


async def test_ids_are_bounded_types_strict_and_conflicts_are_409(cell: FuzzCell) -> None:
    async with httpx.AsyncClient(base_url=cell.url, headers=AUTH) as c:
        r = await c.get("/api/v1/picks/9223372036854775808")  # 2**63: was a 500 OverflowError
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "path.pick_id", r.text
        assert (await c.get("/api/v1/picks/9223372036854775807")).status_code == 404

        r = await c.post("/api/v1/system/start", json={"cycles": False})
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "body.cycles", r.text
        r = await c.post("/api/v1/system/start", json={"cycles": "3"})
        assert r.status_code == 422, r.text
        r = await c.post("/api/v1/calibration/handshake", json={"num_poses": 8.0})  # JSON's integer
        assert r.status_code == 202, r.text

        r = await c.post("/api/v1/system/start", json={"cycles": 50})
        assert r.status_code == 200, r.text
        r = await c.post("/api/v1/system/start", json={})
        assert r.status_code == 409 and r.json()["error"] == "RobotBusyError", r.text
        assert "already running" in r.json()["detail"]

        r = await c.get("/api/v1/robot/urdf")
        assert r.status_code == 200 and r.headers["content-type"].startswith("application/xml")
        r = await c.request("OPTIONS", "/api/v1/config")
        assert r.status_code == 405 and r.headers["allow"] == "GET, PUT", r.headers
        r = await c.get("/api/v1/calibration/handshake")
        assert r.status_code == 405 and r.headers["allow"] == "POST", r.text
