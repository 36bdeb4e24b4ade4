"""UR joint-state rate and command round trip, against the simulated UR in its own process.

- RTDE packages: how many a ur_rtde receive interface sees per controller second (the controller
  sends 500), and how many reach the driver as FeedbackStates through URLink's poller;
- command round trips over ur_rtde (wall time, the client's view): a dashboard query, a
  register-protocol command (setPayload: sent → script done → cleared → ready), a servoJ target until
  the reported target joints move (controller time and wall time).
"""

from __future__ import annotations

import asyncio
import statistics
import time

import numpy as np

from services.kinematics.robot_models import get_robot
from services.sim.ur.controller import URControllerConfig
from services.sim.ur.process import SimSpec, URSimProcess
from services.sim.ur.server import free_loopback_host

CONFIG = URControllerConfig(power_on_s=0.05, brake_release_s=0.05)
WINDOW_S = 3.0  # controller seconds of feedback counted
ROUND_TRIPS = 200


def _pct(xs: list[float], q: float) -> float:
    return float(np.percentile(np.array(xs), q))


def _receive_rate(host: str) -> None:
    import rtde_receive

    r = rtde_receive.RTDEReceiveInterface(host)
    try:
        seen: set[float] = set()
        t0, w0 = r.getTimestamp(), time.perf_counter()
        while (t := r.getTimestamp()) < t0 + WINDOW_S:
            seen.add(t)
            time.sleep(0.0002)
        wall = time.perf_counter() - w0
        print(
            f"ur_rtde receive: {len(seen) / WINDOW_S:.0f} distinct packages per controller second "
            f"(controller sends 500); controller/wall clock {WINDOW_S / wall:.2f}"
        )
    finally:
        r.disconnect()


async def _link_rate_and_servo(host: str) -> None:
    from services.robot.ur.link import URLink

    link = URLink(host, get_robot("ur5e"))
    await link.connect()
    await link.enable()
    try:
        n = 0
        fb = await link.next_feedback()
        t_end, w0 = fb.timestamp_ms + WINDOW_S * 1000, time.perf_counter()
        while fb.timestamp_ms < t_end:
            fb = await link.next_feedback()
            n += 1
        wall = time.perf_counter() - w0
        print(
            f"URLink feedback: {n / WINDOW_S:.0f} states per controller second, {n / wall:.0f} per wall "
            "second (the rate the robot service publishes joint states)"
        )
        ctrl_ms: list[float] = []
        wall_ms: list[float] = []
        q = fb.q.copy()
        for k in range(40):
            q = q.copy()
            q[5] += 0.002 * (1 if k % 2 == 0 else -1)
            fb0 = await link.next_feedback()
            w = time.perf_counter()
            rid = await link.servo_j(q, 0.02)
            moved = await link.wait_controller(lambda f, q=q: abs(f.q_target[5] - q[5]) < 0.0019, 1.0)
            ctrl_ms.append(moved.timestamp_ms - fb0.timestamp_ms)
            wall_ms.append((time.perf_counter() - w) * 1000)
            await link.wait_motion_done(rid, 2.0)
        print(
            f"servoJ target → reported target joints move: controller median {statistics.median(ctrl_ms):.0f} ms, "
            f"wall median {statistics.median(wall_ms):.1f} ms, p95 {_pct(wall_ms, 95):.1f} ms (n={len(wall_ms)})"
        )
    finally:
        await link.close()


def _round_trips(host: str) -> None:
    import dashboard_client
    import rtde_control

    db = dashboard_client.DashboardClient(host)
    db.connect()
    db.powerOn()
    db.brakeRelease()
    time.sleep(0.3)  # the sim's brake release takes 0.1 s of controller time
    c = rtde_control.RTDEControlInterface(host)
    try:
        dash, reg = [], []
        for _ in range(ROUND_TRIPS):
            w = time.perf_counter()
            db.robotmode()
            dash.append((time.perf_counter() - w) * 1000)
        for _ in range(ROUND_TRIPS):
            w = time.perf_counter()
            assert c.setPayload(0.1, [0.0, 0.0, 0.0])
            reg.append((time.perf_counter() - w) * 1000)
        print(
            f"dashboard robotmode round trip: median {statistics.median(dash):.2f} ms, p95 {_pct(dash, 95):.2f} ms"
        )
        print(
            f"setPayload via the control script (send → done → clear → ready): median "
            f"{statistics.median(reg):.1f} ms, p95 {_pct(reg, 95):.1f} ms (n={ROUND_TRIPS})"
        )
    finally:
        c.stopScript()
        c.disconnect()
        db.disconnect()


def main() -> None:
    with URSimProcess(SimSpec("ur5e", free_loopback_host(), CONFIG)) as sim:
        _receive_rate(sim.host)
        _round_trips(sim.host)
        asyncio.run(_link_rate_and_servo(sim.host))


if __name__ == "__main__":
    main()
