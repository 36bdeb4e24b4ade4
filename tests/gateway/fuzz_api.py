"""The gateway's API contract under schemathesis: a gateway on a free loopback port with a scripted
task service and robot driver behind it, fuzzed by the schemathesis CLI in another process.

``tests/gateway/test_contract.py`` runs a short seeded slice of this; ``make fuzz-api`` runs it long::

    python -m tests.gateway.fuzz_api --max-examples 200 --seed 1
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import tempfile
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pickplace.v1 import common_pb2, robot_pb2, robot_pb2_grpc

from gateway.app import create_app
from gateway.calibration import CalibrationOutcome, Progress
from gateway.server import GatewayServer
from services.common import grpc_util
from services.common.net import free_loopback_port
from services.common.settings import DatabaseSettings, Settings, load_settings
from tests.gateway.conftest import TOKEN, fake_task_service, gateway_settings, migrate_up, pick_event


def camera_jpeg() -> bytes:
    import cv2
    import numpy as np

    ok, buf = cv2.imencode(".jpg", np.full((48, 64, 3), 90, np.uint8))
    assert ok
    return bytes(buf.tobytes())


SCHEMATHESIS = Path(sys.executable).with_name("schemathesis")
CONFIG = Path(__file__).with_name("schemathesis.toml")


class FakeRobotController(robot_pb2_grpc.RobotControllerServicer):
    """The robot driver's status and e-stop calls, answered at once (nothing moves)."""

    def __init__(self) -> None:
        self.estop = False

    async def GetStatus(self, request, context):  # type: ignore[no-untyped-def]
        return robot_pb2.RobotStatus(
            robot_mode=3 if self.estop else 5,
            robot_mode_name="E-STOP" if self.estop else "ENABLE",
            enabled=not self.estop,
            connected=True,
            estop_active=self.estop,
            robot_model="nova5",
        )

    async def EmergencyStop(self, request, context):  # type: ignore[no-untyped-def]
        self.estop = not request.release
        return common_pb2.CommandResponse(success=True, message="released" if request.release else "e-stop")

    async def ClearError(self, request, context):  # type: ignore[no-untyped-def]
        return common_pb2.CommandResponse(success=True, message="cleared")

    async def Enable(self, request, context):  # type: ignore[no-untyped-def]
        return common_pb2.CommandResponse(success=True, message="enabled")


async def instant_calibration(num_poses: int, progress: Progress) -> CalibrationOutcome:
    progress(1.0, "done")
    return CalibrationOutcome({"poses_used": num_poses}, 0.1, "scripted")


def fuzz_settings(work: Path) -> Settings:
    zport = free_loopback_port()
    base = load_settings(
        "sim",
        overrides={
            "logging": {"file": str(work / "pickplace.log")},
            "zenoh": {"listen": [f"tcp/127.0.0.1:{zport}"]},
            "grpc": {"robot_port": free_loopback_port()},
        },
    )
    db = DatabaseSettings(url=f"sqlite+aiosqlite:///{work / 'gateway.db'}")
    return gateway_settings(base, db, work, rpc_timeout_s=1.0, estop_timeout_s=1.0)


@dataclass
class FuzzCell:
    url: str
    robot: FakeRobotController


@asynccontextmanager
async def fuzz_cell(work: Path) -> AsyncIterator[FuzzCell]:
    s = fuzz_settings(work)
    await migrate_up(s.database)
    robot = FakeRobotController()
    server = grpc_util.create_server()
    robot_pb2_grpc.add_RobotControllerServicer_to_server(robot, server)
    grpc_util.bind(server, "127.0.0.1", s.grpc.robot_port)
    await server.start()
    try:
        async with fake_task_service(None, s.cell_id, s.grpc.task_port) as task:
            task.cycle_s = 0.05
            app = create_app(s, calibration_executor=instant_calibration, serve_web=False)
            async with GatewayServer(app, "127.0.0.1", 0) as gw:
                cell = app.state.cell
                for i in range(3):  # a history for GET /picks/{id} to find
                    cell.writer.offer(pick_event(i, success=i != 1))
                await cell.writer.flush(timeout_s=5.0)
                cell.hub.on_camera(camera_jpeg())
                yield FuzzCell(gw.url, robot)
    finally:
        await server.stop(grace=0.2)


@dataclass
class FuzzResult:
    returncode: int
    output: str
    report: dict[str, Any]


async def run_schemathesis(
    url: str, *, seed: int, max_examples: int, report_dir: Path, extra: list[str] | None = None
) -> FuzzResult:
    """The schemathesis CLI against ``url``: all checks, all phases, authenticated, seeded.
    ``report_dir`` absolute (:func:`fresh_dir` makes one): the CLI runs there."""
    args = [
        str(SCHEMATHESIS),
        "--config-file",
        str(CONFIG),
        "run",
        f"{url}/openapi.json",
        "--checks",
        "all",
        "--phases",
        "examples,coverage,fuzzing,stateful",
        "--seed",
        str(seed),
        "--max-examples",
        str(max_examples),
        "--header",
        f"Authorization: Bearer {TOKEN}",
        "--workers",
        "1",
        "--request-timeout",
        "10",
        "--report",
        "ndjson",
        "--report-dir",
        str(report_dir),
        "--no-color",
        *(extra or []),
    ]
    env = {**os.environ, "SCHEMATHESIS_HOOKS": "", "NO_COLOR": "1"}
    proc = await asyncio.create_subprocess_exec(
        *args,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
        env=env,
        cwd=report_dir,  # its example cache (.schemathesis/) goes there, not into the checkout
    )
    out, _ = await proc.communicate()
    return FuzzResult(proc.returncode or 0, out.decode(errors="replace"), summarise(report_dir))


def summarise(report_dir: Path) -> dict[str, Any]:
    """Requests sent and the distinct failures, from schemathesis' ndjson event stream."""
    requests = 0
    failures: set[str] = set()
    for f in sorted(report_dir.glob("*.ndjson")):
        for line in f.read_text().splitlines():
            recorder = (json.loads(line).get("ScenarioFinished") or {}).get("recorder") or {}
            requests += len(recorder.get("interactions") or {})
            for checks in (recorder.get("checks") or {}).values():
                for c in checks:
                    if c.get("status") not in ("success", "skip"):
                        failures.add(f"{recorder.get('label')}: {c.get('name')}")
    return {"requests": requests, "failures": sorted(failures)}


def fresh_dir(path: str) -> Path:
    d = Path(path).resolve()
    d.mkdir(parents=True, exist_ok=True)
    for old in d.glob("*.ndjson"):
        old.unlink()
    return d


async def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--max-examples", type=int, default=200)
    p.add_argument("--max-time", type=int, default=None)
    p.add_argument("--report-dir", default="artifacts/fuzz-api")
    a = p.parse_args(argv)
    report_dir = fresh_dir(a.report_dir)
    with tempfile.TemporaryDirectory(prefix="pickplace-fuzz-") as tmp:
        async with fuzz_cell(Path(tmp)) as cell:
            extra = ["--max-time", str(a.max_time)] if a.max_time else []
            r = await run_schemathesis(
                cell.url, seed=a.seed, max_examples=a.max_examples, report_dir=report_dir, extra=extra
            )
    print(r.output)
    print(f"requests: {r.report['requests']}, failures: {len(r.report['failures'])}")
    for f in r.report["failures"]:
        print("  ", f)
    return r.returncode or (0 if r.report["requests"] else 1)


if __name__ == "__main__":
    raise SystemExit(asyncio.run(main()))
