"""E-stop latency: gRPC EmergencyStop → the controller's e-stop, and → the arm at rest, quiet and with
both cores busy (two spinning processes).

The cell as in ``up --processes``: the simulated controller (MuJoCo twin) in one process, the robot
driver (RobotController gRPC) in another, this bench in a third — a gRPC client like the gateway's,
plus a feedback reader that watches the controller. Each trial starts a MovJ, waits until the arm
moves, presses the e-stop over gRPC and waits for the controller to report it (SafetyState) and the
arm to be at rest (every joint speed under 0.01 rad/s), then releases and recovers.

Figures on the controller's clock: the e-stop's instant is placed on it from the newest packet before
it (its stamp + the host time since that packet arrived), and the e-stop / rest instants are the stamps
of the first packets that show them (8 ms feedback period, 1 ms stamps: the figures include up to one
period of quantisation). Also: the same on the host's clock (packet receipt), and the RPC's own reply.

BENCH_ESTOP_TRIALS (60) trials per phase; BENCH_ESTOP_NICE=-10 runs the driver's process as
``robot.process_nice: -10`` would (needs CAP_SYS_NICE).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field

import numpy as np

REST_RAD_S = 0.01
TRIALS = int(os.environ.get("BENCH_ESTOP_TRIALS", "60"))
TARGETS = ([40.0, 10.0, 80.0, 0.0, -90.0, 0.0], [-40.0, -10.0, 100.0, 0.0, -90.0, 0.0])


def _settings(**robot: object):  # type: ignore[no-untyped-def]
    from services.common.settings import load_settings

    return load_settings(
        "sim", overrides={"logging": {"file": None}, "grpc": {"robot_port": 0}, "robot": robot}
    )


async def _controller() -> None:
    """Child: the simulated controller on free ports; prints them, runs until stdin closes."""
    from services.sim.app import build_sim_server

    s = _settings()
    async with build_sim_server(s, "twin", ports={"dashboard": 0, "feedback": 0, "slow": 0}) as sim:
        print(json.dumps(sim.ports), flush=True)
        await asyncio.to_thread(sys.stdin.read)


async def _driver(dashboard: int, feedback: int) -> None:
    """Child: the robot driver service against that controller; prints its gRPC port."""
    from services.robot.service import RobotService

    s = _settings(dashboard_port=dashboard, feedback_port=feedback)
    async with RobotService(s, grpc_port=0) as svc:
        print(json.dumps({"grpc": svc.grpc_port}), flush=True)
        await asyncio.to_thread(sys.stdin.read)


@dataclass
class Observer:
    """Every packet the controller sends: (stamp ms, host receipt ns, e-stop, max joint speed)."""

    packets: list[tuple[int, int, bool, float]] = field(default_factory=list)
    changed: asyncio.Event = field(default_factory=asyncio.Event)

    def on_feedback(self, fb) -> None:  # type: ignore[no-untyped-def]
        self.packets.append((fb.timestamp_ms, fb.received_ns, fb.estop, float(np.max(np.abs(fb.qd)))))
        self.changed.set()

    async def first(self, since: int, pred) -> tuple[int, int, bool, float]:  # type: ignore[no-untyped-def]
        async with asyncio.timeout(10.0):
            while True:
                for p in self.packets[since:]:
                    if pred(p):
                        return p
                self.changed.clear()
                await self.changed.wait()


async def _child(*args: str) -> tuple[asyncio.subprocess.Process, dict[str, int]]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "bench.bench_estop",
        *args,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,  # the children's logs (an alarm 116 per trial) would drown the figures
    )
    assert proc.stdout is not None
    async with asyncio.timeout(120):
        line = await proc.stdout.readline()
    if not line:
        raise RuntimeError(f"bench child {args[0]} exited before it was ready (rc {await proc.wait()})")
    return proc, json.loads(line)


async def _trials(stub, obs: Observer, n: int) -> dict[str, list[float]]:  # type: ignore[no-untyped-def]
    from pickplace.v1 import robot_pb2

    out: dict[str, list[float]] = {
        "stop_ctrl": [],
        "rest_ctrl": [],
        "stop_host": [],
        "rest_host": [],
        "rpc": [],
    }
    for k in range(n):
        await stub.EmergencyStop(robot_pb2.EmergencyStopRequest(release=True))
        await stub.ClearError(robot_pb2.ClearErrorRequest())
        await stub.Enable(robot_pb2.EnableRequest())
        target = np.deg2rad(TARGETS[k % 2]).tolist()
        move = asyncio.ensure_future(
            stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=target, speed_ratio=60))
        )
        mark = len(obs.packets)
        await obs.first(mark, lambda p: p[3] > 0.3)  # moving
        s0, r0, _, _ = obs.packets[-1]
        t_issue = time.time_ns()
        await stub.EmergencyStop(robot_pb2.EmergencyStopRequest())
        t_reply = time.time_ns()
        since = len(obs.packets) - 1
        s1, r1, _, _ = await obs.first(since, lambda p: p[2])
        s2, r2, _, _ = await obs.first(since, lambda p: p[2] and p[3] < REST_RAD_S)
        issue_ctrl = s0 + (t_issue - r0) / 1e6
        out["stop_ctrl"].append(s1 - issue_ctrl)
        out["rest_ctrl"].append(s2 - issue_ctrl)
        out["stop_host"].append((r1 - t_issue) / 1e6)
        out["rest_host"].append((r2 - t_issue) / 1e6)
        out["rpc"].append((t_reply - t_issue) / 1e6)
        with contextlib.suppress(Exception):
            await move  # fails as EmergencyStopError
    return out


def _pct(xs: list[float]) -> str:
    a = np.asarray(xs)
    return f"p50 {np.percentile(a, 50):6.1f} ms  p99 {np.percentile(a, 99):6.1f} ms  max {a.max():6.1f} ms"


def _report(label: str, r: dict[str, list[float]]) -> None:
    n = len(r["rpc"])
    print(f"e-stop ({label}, n={n}):")
    print(f"  gRPC EmergencyStop → e-stop at the controller (controller clock): {_pct(r['stop_ctrl'])}")
    print(f"  gRPC EmergencyStop → arm at rest (controller clock):              {_pct(r['rest_ctrl'])}")
    print(f"  → e-stop seen in feedback (host clock):                           {_pct(r['stop_host'])}")
    print(f"  → at rest seen in feedback (host clock):                          {_pct(r['rest_host'])}")
    print(f"  EmergencyStop RPC answered (host clock):                          {_pct(r['rpc'])}")


async def _run() -> None:
    import grpc  # noqa: F401  (the stubs need it loaded)
    from pickplace.v1 import robot_pb2_grpc

    from services.common.grpc_util import channel
    from services.robot.client import DobotClient

    ctl, ports = await _child("controller")
    drv = None
    spinners: list[asyncio.subprocess.Process] = []
    try:
        drv, g = await _child("driver", str(ports["dashboard"]), str(ports["feedback"]))
        obs = Observer()
        async with (
            DobotClient("127.0.0.1", ports["dashboard"], ports["feedback"]) as watcher,
            channel("127.0.0.1", g["grpc"]) as ch,
        ):
            watcher.add_listener(obs.on_feedback)
            stub = robot_pb2_grpc.RobotControllerStub(ch)
            await _trials(stub, obs, 3)  # warm up
            _report("quiet", await _trials(stub, obs, TRIALS))
            spin = "while True: pass"
            spinners = [await asyncio.create_subprocess_exec(sys.executable, "-c", spin) for _ in range(2)]
            _report("both cores busy: 2 spinning processes", await _trials(stub, obs, TRIALS))
    finally:
        for sp in spinners:
            sp.kill()
            await sp.wait()
        for proc in (drv, ctl):
            if proc is not None and proc.returncode is None:
                assert proc.stdin is not None
                proc.stdin.close()
                try:
                    async with asyncio.timeout(10):
                        await proc.wait()
                except TimeoutError:
                    proc.kill()


def main() -> None:
    asyncio.run(_run())


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "driver" and os.environ.get("BENCH_ESTOP_NICE"):
        from services.robot.service import set_process_nice

        set_process_nice(int(os.environ["BENCH_ESTOP_NICE"]))  # as robot.process_nice does in serve
    if len(sys.argv) > 1 and sys.argv[1] == "controller":
        asyncio.run(_controller())
    elif len(sys.argv) > 1 and sys.argv[1] == "driver":
        asyncio.run(_driver(int(sys.argv[2]), int(sys.argv[3])))
    else:
        main()
