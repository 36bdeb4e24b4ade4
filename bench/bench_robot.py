"""Robot link figures: dashboard round trip, joint-state stream rate and added latency."""

from __future__ import annotations

import asyncio
import time

import numpy as np
from pickplace.v1 import common_pb2, robot_pb2, robot_pb2_grpc

from services.common.bus import Bus
from services.common.grpc_util import channel
from services.common.keys import CellKeys
from services.common.net import free_loopback_port
from services.common.settings import load_settings
from services.robot.client import DobotClient
from services.robot.service import RobotService
from services.sim.app import build_sim_server


def _pct(xs: list[float]) -> str:
    a = np.asarray(xs)
    return f"p50 {np.percentile(a, 50):.3f} ms, p99 {np.percentile(a, 99):.3f} ms (n={a.size})"


async def _run() -> None:
    z1, z2 = free_loopback_port(), free_loopback_port()
    s = load_settings(
        "sim",
        overrides={
            "logging": {"file": None},
            "zenoh": {"listen": [f"tcp/127.0.0.1:{z1}"]},
            "grpc": {"robot_port": 0},
        },
    )
    async with build_sim_server(s, "kinematic", ports={"dashboard": 0, "feedback": 0, "slow": 0}) as sim:
        r = s.robot.model_copy(
            update={"dashboard_port": sim.ports["dashboard"], "feedback_port": sim.ports["feedback"]}
        )
        s = s.model_copy(update={"robot": r})

        # 1. dashboard round trip (a separate client, like an operator tool)
        async with DobotClient("127.0.0.1", sim.ports["dashboard"], sim.ports["feedback"]) as c:
            for _ in range(50):
                await c.raw_request("RobotMode()")
            rtt = []
            for _ in range(2000):
                t0 = time.perf_counter_ns()
                await c.raw_request("RobotMode()")
                rtt.append((time.perf_counter_ns() - t0) / 1e6)
            print(f"dashboard round trip RobotMode(): {_pct(rtt)}")

        async with Bus(s.zenoh) as bus, RobotService(s, bus, grpc_port=0) as svc:
            # 2. gRPC stream: rate and latency (driver receipt → client), (controller stamp → client)
            ch = channel("127.0.0.1", svc.grpc_port)
            async with ch:
                stub = robot_pb2_grpc.RobotControllerStub(ch)
                stream = stub.StreamJointStates(robot_pb2.StreamJointStatesRequest())
                await stream.read()
                lat_driver, lat_ctrl = [], []
                t0 = time.perf_counter()
                n = 0
                while time.perf_counter() - t0 < 3.0:
                    msg = await stream.read()
                    now = time.time_ns()
                    lat_driver.append((now - msg.header.stamp_ns) / 1e6)
                    lat_ctrl.append((now - msg.source_stamp_ns) / 1e6)
                    n += 1
                stream.cancel()
                print(f"gRPC StreamJointStates: {n / (time.perf_counter() - t0):.1f} msg/s")
                print(f"  added latency driver → gRPC client: {_pct(lat_driver)}")
                print(
                    f"  feedback packet (controller TimeStamp, 1 ms resolution) → gRPC client: {_pct(lat_ctrl)}"
                )

            # 3. Zenoh subscriber in a second session
            zs = s.zenoh.model_copy(update={"listen": [f"tcp/127.0.0.1:{z2}"], "connect": s.zenoh.listen})
            async with Bus(zs) as bus2:
                sub = bus2.subscribe(CellKeys(s.cell_id).joint_states, common_pb2.JointState, maxsize=4096)
                await sub.get(5.0)
                lat_z, lat_zc = [], []
                t0 = time.perf_counter()
                n = 0
                while time.perf_counter() - t0 < 3.0:
                    msg = await sub.get(2.0)
                    now = time.time_ns()
                    lat_z.append((now - msg.header.stamp_ns) / 1e6)
                    lat_zc.append((now - msg.source_stamp_ns) / 1e6)
                    n += 1
                sub.close()
                print(f"Zenoh joint_states subscriber: {n / (time.perf_counter() - t0):.1f} msg/s")
                print(f"  added latency driver → Zenoh subscriber: {_pct(lat_z)}")
                print(
                    f"  feedback packet (controller TimeStamp, 1 ms resolution) → Zenoh subscriber: {_pct(lat_zc)}"
                )


def main() -> None:
    asyncio.run(_run())


if __name__ == "__main__":
    main()
