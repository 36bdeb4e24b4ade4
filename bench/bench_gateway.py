"""Gateway figures: requests/s and p50/p99 latency of GET /system/status and GET /picks with 100k picks
in PostgreSQL, and e-stop latency (REST request → EmergencyStop received by the simulated Dobot).

The gateway runs as its own process (``pickplace serve gateway``, as deployed). The status figure
comes from a load generator in a third process: wrk (Debian's ``wrk``: ``make bench`` installs it
with ``apt-get install -y wrk`` when missing) with 16 connections for 10 s, or, without wrk, an httpx
generator in a subprocess; target ≥ 3,000 req/s and p99 ≤ 10 ms. It is measured twice: with the
gateway idle, and with it as busy as in a running cell (:class:`BusyCell`: joint states at 125 Hz,
robot and task status at 2 Hz, detections, the vision image and 640×480 RGB-D frames over Zenoh, a
pick every 2 s written to PostgreSQL, three dashboards on the WebSocket and one polling the camera
views). The machine's load average is printed beside each figure. The other reads use an httpx generator in this process, next to the robot-driver
service and the simulated Dobot. Everything on 127.0.0.1; the PostgreSQL schema is created for the
run and dropped after it.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import numpy as np

from gateway.db import migrate
from gateway.db.engine import make_engine
from gateway.db.models import Pick
from services.common.net import free_loopback_port
from services.common.settings import REPO_ROOT, DatabaseSettings, load_settings

PG_URL = os.environ.get("PICKPLACE_TEST_POSTGRES_URL", "postgresql+asyncpg://postgres@127.0.0.1:5432/test")
ROWS = 100_000
TOKEN = "bench-token-0123456789abcdef"
CONCURRENCY = 16
REQUESTS = 1000
ESTOPS = 200
STATUS_SECONDS = 10
STATUS_TARGET_RPS = 3000
STATUS_TARGET_P99_MS = 10.0
STARTUP_S = 120.0  # a safety net: a gateway starting beside 25 runnable processes took over 30 s


def _pct(ms: list[float]) -> str:
    a = np.asarray(ms)
    return f"p50 {np.percentile(a, 50):.2f} ms, p99 {np.percentile(a, 99):.2f} ms (n={a.size})"


async def _fill(db: DatabaseSettings) -> float:
    engine = make_engine(db, db.url)
    t0 = time.perf_counter()
    try:
        await migrate.upgrade(engine, db)
        rng = np.random.default_rng(0)
        start = datetime.now(UTC) - timedelta(days=30)
        async with engine.begin() as conn:
            for base in range(0, ROWS, 10_000):
                rows = []
                for i in range(base, base + 10_000):
                    ok = bool(rng.random() < 0.93)
                    rows.append(
                        {
                            "pick_id": uuid.UUID(int=int(rng.integers(0, 2**63)) << 64 | i).hex,
                            "timestamp": start + timedelta(seconds=26 * i),
                            "robot_id": "robot_01",
                            "object_class": "rod" if i % 3 else "cube_red",
                            "pick_pose": {"x": 0.45, "y": 0.0, "z": 0.02, "qx": 0, "qy": 0, "qz": 0, "qw": 1},
                            "place_pose": None,
                            "grasp_quality": float(rng.uniform(0.5, 1)),
                            "cycle_time": float(rng.normal(9, 1)),
                            "success": ok,
                            "error_code": None if ok else "GraspFailureError",
                            "error_message": None if ok else "object slipped",
                            "task": "stand-rod",
                            "stage_reached": "DONE" if ok else "LIFT",
                            "stage_durations": {"PLAN": 0.5},
                            "attempts": 1,
                        }
                    )
                await conn.execute(Pick.__table__.insert(), rows)
        async with engine.connect() as conn:  # what autovacuum would do soon after such a load
            await conn.execution_options(isolation_level="AUTOCOMMIT")
            await conn.exec_driver_sql("ANALYZE picks")
    finally:
        await engine.dispose()
    return time.perf_counter() - t0


def _start_gateway(
    db: DatabaseSettings, port: int, robot_port: int, tmp: Path, zenoh_port: int | None = None
) -> subprocess.Popen[bytes]:
    env = {
        **os.environ,
        "PICKPLACE_GATEWAY__API_TOKEN": TOKEN,
        "PICKPLACE_GATEWAY__PORT": str(port),
        "PICKPLACE_GATEWAY__EDGE_GRPC_PORT": str(free_loopback_port()),
        "PICKPLACE_GATEWAY__PICK_SPILL_FILE": str(tmp / "spill.jsonl"),
        "PICKPLACE_GATEWAY__HEALTH_PERIOD_S": "60",
        "PICKPLACE_DATABASE__URL": db.url,
        "PICKPLACE_GRPC__ROBOT_PORT": str(robot_port),
        "PICKPLACE_GRPC__TASK_PORT": str(free_loopback_port()),
        "PICKPLACE_ZENOH__LISTEN": f'["tcp/127.0.0.1:{zenoh_port or free_loopback_port()}"]',
        "PICKPLACE_LOGGING__FILE": str(tmp / "gateway.log"),
        "PICKPLACE_LOGGING__LEVEL": "WARNING",
    }
    env.pop("DATABASE_URL", None)
    if db.schema_name:
        env["PICKPLACE_DATABASE__SCHEMA_NAME"] = db.schema_name
    out_path = tmp / f"gateway-{port}.out"
    with out_path.open("wb") as out:  # a configuration error is printed here
        proc = subprocess.Popen(
            [sys.executable, "-m", "services.apps.cli", "serve", "gateway"],
            cwd=REPO_ROOT,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    GATEWAY_OUT[proc.pid] = out_path
    return proc


def gateway_output(proc: subprocess.Popen[bytes]) -> str:
    """What a gateway started by :func:`_start_gateway` printed (it names a configuration error)."""
    path = GATEWAY_OUT.get(proc.pid)
    return path.read_text(errors="replace")[-2000:] if path is not None else ""


GATEWAY_OUT: dict[int, Path] = {}


async def _wait_up(url: str, proc: subprocess.Popen[bytes]) -> None:
    async with httpx.AsyncClient() as c:
        deadline = time.monotonic() + STARTUP_S
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                text = await asyncio.to_thread(gateway_output, proc)
                raise RuntimeError(f"gateway exited (rc {proc.returncode}): {text}")
            try:
                if (await c.get(url + "/api/v1/system/status")).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            await asyncio.sleep(0.1)
    raise RuntimeError(f"gateway did not come up in {STARTUP_S:.0f} s")


async def _load(url: str, path: str) -> tuple[float, list[float]]:
    lat: list[float] = []
    todo = iter(range(REQUESTS))
    limits = httpx.Limits(max_connections=CONCURRENCY, max_keepalive_connections=CONCURRENCY)
    async with httpx.AsyncClient(base_url=url, limits=limits, timeout=30) as c:
        for _ in range(50):
            (await c.get(path)).raise_for_status()

        async def worker() -> None:
            for _ in todo:
                t0 = time.perf_counter()
                r = await c.get(path)
                lat.append((time.perf_counter() - t0) * 1e3)
                r.raise_for_status()

        t0 = time.perf_counter()
        await asyncio.gather(*(worker() for _ in range(CONCURRENCY)))
        return REQUESTS / (time.perf_counter() - t0), lat


def _wrk(url: str, seconds: int) -> tuple[float, float, float]:
    """(req/s, p50 ms, p99 ms) of wrk -c16 against ``url``, one thread (the machine has two cores)."""
    out = subprocess.run(
        ["wrk", "-t1", f"-c{CONCURRENCY}", f"-d{seconds}s", "--latency", url],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    if "Non-2xx" in out or "Socket errors" in out:
        raise RuntimeError(f"wrk saw errors:\n{out}")
    rps = float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1))  # type: ignore[union-attr]
    pct = {p: _ms(v) for p, v in re.findall(r"^\s+(50|99)%\s+(\S+)$", out, re.M)}
    return rps, pct["50"], pct["99"]


def _ms(text: str) -> float:
    for unit, scale in (("us", 1e-3), ("ms", 1.0), ("s", 1e3)):
        if text.endswith(unit):
            return float(text[: -len(unit)]) * scale
    raise ValueError(f"wrk latency {text!r}")


HTTPX_GENERATOR = """
import asyncio, sys, time, httpx, json
url, n, conc = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
async def main():
    lat = []
    todo = iter(range(n))
    limits = httpx.Limits(max_connections=conc, max_keepalive_connections=conc)
    async with httpx.AsyncClient(limits=limits, timeout=30) as c:
        async def worker():
            for _ in todo:
                t0 = time.perf_counter(); r = await c.get(url); lat.append(time.perf_counter() - t0)
                r.raise_for_status()
        t0 = time.perf_counter()
        await asyncio.gather(*(worker() for _ in range(conc)))
        print(json.dumps({"rps": n / (time.perf_counter() - t0), "lat": lat}))
asyncio.run(main())
"""


def _httpx_subprocess(url: str, n: int) -> tuple[float, float, float]:
    out = subprocess.run(
        [sys.executable, "-c", HTTPX_GENERATOR, url, str(n), str(CONCURRENCY)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    doc = json.loads(out)
    lat = np.asarray(doc["lat"]) * 1e3
    return float(doc["rps"]), float(np.percentile(lat, 50)), float(np.percentile(lat, 99))


def status_load(url: str, label: str) -> None:
    """GET /system/status under 16 connections from another process; prints the figure and the target."""
    target = f"{url}/api/v1/system/status"
    if shutil.which("wrk"):
        _wrk(target, 2)  # warm-up
        rps, p50, p99 = _wrk(target, STATUS_SECONDS)
        tool = f"wrk -t1 -c{CONCURRENCY} -d{STATUS_SECONDS}s"
    else:
        rps, p50, p99 = _httpx_subprocess(target, 20_000)
        tool = f"httpx generator in a subprocess, {CONCURRENCY} connections (install wrk for the real figure)"
    ok = rps >= STATUS_TARGET_RPS and p99 <= STATUS_TARGET_P99_MS
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(
        f"GET /api/v1/system/status, gateway {label} ({tool}): {rps:6.0f} req/s, p50 {p50:.2f} ms, "
        f"p99 {p99:.2f} ms — target ≥ {STATUS_TARGET_RPS} req/s, p99 ≤ {STATUS_TARGET_P99_MS:g} ms: "
        f"{'met' if ok else 'MISSED'} (load average {load})"
    )


class BusyCell:
    """What keeps a cell's gateway busy, from outside its process: the cell's Zenoh streams at their
    rates (a thread of this process), three dashboards on the WebSocket and one asking for the camera
    views (tasks of this process's loop). ``async with BusyCell(url, zenoh_port): ...``"""

    JOINT_HZ = 125.0
    FRAME_EVERY = 12  # joint states per RGB-D frame (~10 Hz)
    VISION_EVERY = 25  # per detections + vision image (5 Hz)
    STATUS_EVERY = 62  # per robot/task status (2 Hz)
    PICK_EVERY = 250  # per pick event (every 2 s, written to the database)
    DASHBOARDS = 3

    def __init__(self, url: str, zenoh_port: int, cell_id: str = "cell1"):
        self.url = url
        self.zenoh_port = zenoh_port
        self.cell_id = cell_id
        self.stop = threading.Event()
        self.published = 0
        self.received = 0
        self.images = 0
        self._thread = threading.Thread(target=self._publish, name="busy-cell", daemon=True)
        self._tasks: list[asyncio.Task[None]] = []
        self._flowing = asyncio.Event()

    async def __aenter__(self) -> BusyCell:
        self._thread.start()
        ws_url = self.url.replace("http://", "ws://") + "/api/v1/live"
        self._tasks = [asyncio.create_task(self._dashboard(ws_url)) for _ in range(self.DASHBOARDS)]
        self._tasks.append(asyncio.create_task(self._camera()))
        async with asyncio.timeout(30):  # until the gateway shows the streams (bus connected)
            await self._flowing.wait()
        return self

    def _check_flowing(self) -> None:
        if self.received >= 100 and self.images > 0:
            self._flowing.set()

    async def __aexit__(self, *exc: object) -> None:
        self.stop.set()
        for t in self._tasks:
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await asyncio.to_thread(self._thread.join, 10)

    async def _dashboard(self, ws_url: str) -> None:
        import websockets

        async with websockets.connect(ws_url, max_size=None) as ws:
            async for _ in ws:
                self.received += 1
                self._check_flowing()

    async def _camera(self) -> None:
        async with httpx.AsyncClient(base_url=self.url, timeout=30) as c:
            while True:
                for view in ("color", "depth", "overlay"):
                    r = await c.get("/api/v1/camera/latest.jpg", params={"view": view})
                    self.images += r.status_code == 200
                    self._check_flowing()
                    await asyncio.sleep(0.2)

    def _publish(self) -> None:
        import cv2
        from pickplace.v1 import common_pb2, robot_pb2, task_pb2, vision_pb2

        from services.common.bus import Bus
        from services.common.keys import CellKeys
        from services.common.settings import ZenohSettings

        keys = CellKeys(self.cell_id)
        rng = np.random.default_rng(0)
        w, h = 640, 480
        color = rng.integers(0, 255, (h, w, 3), np.uint8)
        frame = vision_pb2.RGBDFrame(
            color_rgb8=color.tobytes(),
            depth_u16=rng.integers(400, 900, (h, w)).astype("<u2").tobytes(),
            depth_scale=1e-3,
        )
        frame.intrinsics.width, frame.intrinsics.height = w, h
        frame_bytes = frame.SerializeToString()
        jpeg = vision_pb2.DebugImage(jpeg=cv2.imencode(".jpg", color)[1].tobytes()).SerializeToString()
        names = [f"joint{i}" for i in range(1, 7)]
        zenoh = ZenohSettings(listen=[], connect=[f"tcp/127.0.0.1:{self.zenoh_port}"])
        with Bus(zenoh) as bus:
            t0, n = time.monotonic(), 0
            while not self.stop.is_set():
                n += 1
                js = common_pb2.JointState(
                    name=names,
                    position=[0.1 * i + 1e-3 * n for i in range(6)],
                    velocity=[0.01] * 6,
                    tcp_force=[0.0] * 6,
                    source_stamp_ns=n * 8_000_000,
                )
                js.header.seq, js.header.stamp_ns = n, time.time_ns()
                bus.publish(keys.joint_states, js)
                if n % self.FRAME_EVERY == 0:
                    bus.publish(keys.camera_frames, frame_bytes)
                if n % self.VISION_EVERY == 0:
                    bus.publish(keys.vision_debug_image, jpeg)
                    det = vision_pb2.DetectedObjects()
                    det.header.seq = n
                    for _ in range(3):
                        det.cubes.add(color_label="red", has_base=True)
                    bus.publish(keys.detected_objects, det)
                if n % self.STATUS_EVERY == 0:
                    k = n // self.STATUS_EVERY
                    bus.publish(keys.robot_status, robot_pb2.RobotStatus(connected=True, robot_mode=7))
                    bus.publish(
                        keys.task_status,
                        task_pb2.TaskStatus(state=("DETECT", "PLAN")[k % 2], running=True, cycle_index=k),
                    )
                if n % self.PICK_EVERY == 0:
                    ev = task_pb2.PickEvent(pick_id=uuid.uuid4().hex, robot_id="robot_01", object_class="rod")
                    ev.header.stamp_ns = time.time_ns()
                    ev.success, ev.stage_reached, ev.cycle_time_s, ev.attempts = True, "DONE", 9.0, 1
                    ev.pick_pose.qw = ev.place_pose.qw = 1.0
                    bus.publish(keys.pick_events, ev)
                self.published = n
                time.sleep(max(0.0, t0 + n / self.JOINT_HZ - time.monotonic()))


async def _run() -> None:
    import asyncpg

    from services.common.bus import Bus
    from services.robot.service import RobotService
    from services.sim.app import build_sim_server

    schema = f"gw_bench_{uuid.uuid4().hex[:10]}"
    dsn = PG_URL.replace("postgresql+asyncpg://", "postgresql://")
    admin = await asyncpg.connect(dsn, timeout=5)
    await admin.execute(f'CREATE SCHEMA "{schema}"')
    try:
        db = DatabaseSettings(url=PG_URL, schema_name=schema)
        print(f"filled {ROWS} picks into PostgreSQL in {await _fill(db):.1f}s")
        with tempfile.TemporaryDirectory() as tmp:
            # 1. read load: the gateway alone (no robot driver to poll), the client in this process
            port, zenoh_port = free_loopback_port(), free_loopback_port()
            proc = _start_gateway(db, port, free_loopback_port(), Path(tmp), zenoh_port)
            try:
                url = f"http://127.0.0.1:{port}"
                await _wait_up(url, proc)
                await asyncio.to_thread(status_load, url, "idle")
                async with BusyCell(url, zenoh_port) as busy:
                    await asyncio.to_thread(status_load, url, "busy")
                print(
                    f"  busy cell: {busy.published} joint states published, {busy.received} WebSocket "
                    f"messages and {busy.images} camera images received"
                )
                for path in (
                    "/api/v1/system/status",
                    "/api/v1/picks?limit=100&offset=0",
                    "/api/v1/picks?limit=100&offset=50000",
                    "/api/v1/metrics",
                ):
                    rps, lat = await _load(url, path)
                    print(f"GET {path}: {rps:6.0f} req/s, {_pct(lat)} ({CONCURRENCY} concurrent)")
                cpu = _cpu_seconds(proc.pid)
                if cpu is not None:
                    print(
                        f"gateway process CPU over the read load: {cpu:.1f} s for {4 * (REQUESTS + 50)} requests"
                    )
            finally:
                _stop_gateway(proc)
            # 2. e-stop through the real robot driver to the simulated Dobot (200 of them: the
            # controller's alarm warning for each is expected here, not news)
            logging.getLogger("pickplace.sim.controller").setLevel(logging.ERROR)
            s = load_settings(
                "sim",
                overrides={
                    "logging": {"file": None},
                    "grpc": {"robot_port": 0},
                    "zenoh": {"listen": [f"tcp/127.0.0.1:{free_loopback_port()}"]},
                },
            )
            async with build_sim_server(
                s, "kinematic", ports={"dashboard": 0, "feedback": 0, "slow": 0}
            ) as sim:
                r = s.robot.model_copy(
                    update={"dashboard_port": sim.ports["dashboard"], "feedback_port": sim.ports["feedback"]}
                )
                s = s.model_copy(update={"robot": r})
                async with Bus(s.zenoh) as bus, RobotService(s, bus, grpc_port=0) as robot:
                    await robot.driver.enable()
                    port = free_loopback_port()
                    proc = _start_gateway(db, port, robot.grpc_port, Path(tmp))
                    try:
                        url = f"http://127.0.0.1:{port}"
                        await _wait_up(url, proc)
                        await _estop(url, sim, robot)
                    finally:
                        _stop_gateway(proc)
    finally:
        await admin.execute(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE')
        await admin.close()


def _stop_gateway(proc: subprocess.Popen[bytes], timeout_s: float = 60.0) -> None:
    """SIGTERM and wait for its shutdown (slow on a loaded machine); killed if it takes longer."""
    proc.terminate()
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        print(f"gateway did not stop within {timeout_s:.0f} s of SIGTERM: killed")
        proc.kill()
        proc.wait()


async def _estop(url: str, sim, robot) -> None:  # type: ignore[no-untyped-def]
    """REST request sent → EmergencyStop(…) parsed by the simulated controller."""
    received: list[float] = []
    original = sim.controller.handle

    def handle(text: str) -> str:
        if text.startswith("EmergencyStop(") and not text.startswith("EmergencyStop(0"):
            received.append(time.perf_counter())
        return original(text)

    sim.controller.handle = handle
    lat: list[float] = []
    try:
        async with httpx.AsyncClient(base_url=url, headers={"Authorization": f"Bearer {TOKEN}"}) as c:
            for i in range(ESTOPS + 10):
                n = len(received)
                t0 = time.perf_counter()
                r = await c.post("/api/v1/system/estop")
                r.raise_for_status()
                if len(received) != n + 1:
                    raise RuntimeError(f"e-stop {i} not seen by the simulated controller")
                if i >= 10:  # warm-up
                    lat.append((received[-1] - t0) * 1e3)
                await robot.driver.emergency_stop(release=True)
    finally:
        sim.controller.handle = original
    print(f"e-stop, REST request → EmergencyStop at the simulated Dobot: {_pct(lat)}")


def _cpu_seconds(pid: int) -> float | None:
    try:
        import psutil

        t = psutil.Process(pid).cpu_times()
        return float(t.user + t.system)
    except Exception:
        return None


def main() -> None:
    asyncio.run(_run())


if __name__ == "__main__":
    main()
