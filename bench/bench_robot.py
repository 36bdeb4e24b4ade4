"""Robot link figures: dashboard round trip, joint-state stream rate and added latency; limits under
concurrent random requests (a recording TCP proxy between the driver and the controller: commands
outside the joint, speed, acceleration or workspace limits); link recovery after outages."""

from __future__ import annotations

import asyncio
import contextlib
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


# ---------------------------------------------------------------------- limits fuzz
class RecordingProxy:
    """A TCP proxy in front of the controller's dashboard and feedback ports: every command the driver
    sends is recorded with the newest feedback the proxy had passed on (the arm's state when it left)."""

    def __init__(self, target_dashboard: int, target_feedback: int):
        self.targets = {"dashboard": target_dashboard, "feedback": target_feedback}
        self.commands: list[tuple[str, np.ndarray, int]] = []  # (command, QActual rad, RobotMode)
        self._q = np.zeros(6)
        self._mode = 0
        self._servers: list[asyncio.base_events.Server] = []
        self.ports: dict[str, int] = {}

    async def __aenter__(self) -> RecordingProxy:
        for name in ("dashboard", "feedback"):
            srv = await asyncio.start_server(self._handler(name), "127.0.0.1", 0)
            self._servers.append(srv)
            self.ports[name] = srv.sockets[0].getsockname()[1]
        return self

    async def __aexit__(self, *exc: object) -> None:
        for srv in self._servers:
            srv.close()

    def _handler(self, name: str):  # type: ignore[no-untyped-def]
        from services import dobot

        async def pump(src: asyncio.StreamReader, dst: asyncio.StreamWriter, tap) -> None:  # type: ignore[no-untyped-def]
            with contextlib.suppress(ConnectionError, asyncio.CancelledError):
                while data := await src.read(65536):
                    tap(data)
                    dst.write(data)
                    await dst.drain()
            dst.close()

        async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            up_r, up_w = await asyncio.open_connection("127.0.0.1", self.targets[name])
            if name == "dashboard":
                framer = dobot.CommandFramer()

                def to_ctl(data: bytes) -> None:
                    for cmd in framer.feed(data):
                        self.commands.append((cmd, self._q.copy(), self._mode))

                def from_ctl(data: bytes) -> None:
                    pass
            else:
                fb = dobot.FeedbackFramer()

                def to_ctl(data: bytes) -> None:
                    pass

                def from_ctl(data: bytes) -> None:
                    for rec in fb.feed(data):
                        self._q = np.deg2rad(np.array(rec["QActual"], dtype=float))
                        self._mode = int(rec["RobotMode"])

            await asyncio.gather(pump(reader, up_w, to_ctl), pump(up_r, writer, from_ctl))

        return handle


def limit_violations(commands: list[tuple[str, np.ndarray, int]], limits) -> tuple[int, int, list[str]]:  # type: ignore[no-untyped-def]
    """Motion commands on the wire outside joint, workspace, speed or acceleration limits (an
    independent check of what was sent): (violations, motion commands, first few described). A ServoJ
    that follows another continues its stream; any other starts from the arm's state when it left."""
    from services import dobot
    from services.common.errors import LimitViolationError
    from services.robot.safety import ACCELERATION_MARGIN

    spec = limits.spec
    vmax = spec.max_velocity * limits.velocity_scale * (1 + 1e-6)
    amax = spec.max_acceleration * ACCELERATION_MARGIN
    bad: list[str] = []
    n = 0
    before = ""  # the command before (for the description)
    prev: list[np.ndarray] = []  # the stream's last two targets (oldest first)
    for cmd, q_meas, mode in commands:
        parsed = dobot.parse_command(cmd)
        if parsed.key not in ("servoj", "movj", "movl"):
            prev = []
            before = cmd
            continue
        n += 1
        values = (
            parsed.args[:6]
            if parsed.key == "servoj"
            else parsed.kwargs.get("joint", "").strip("{}").split(",")
        )
        q = np.deg2rad([float(a) for a in values])
        why = None
        try:
            limits.check_all(q)
        except LimitViolationError as exc:
            why = str(exc)
        if parsed.key == "servoj":
            t = float(parsed.kwargs.get("t", "0.1"))
            if not prev:
                prev = [q_meas, q_meas]  # a new stream: from the arm at rest where it is
            elif mode == int(dobot.RobotMode.ENABLE) and np.max(np.abs(q_meas - prev[-1])) <= 1e-3:
                prev = [prev[-1], prev[-1]]  # it ran dry and rests at the last target: from rest again
            speed = np.abs(q - prev[-1]) / t
            acc = np.abs(q - 2 * prev[-1] + prev[-2]) / t**2
            if why is None and np.any(speed > vmax):
                why = f"speed {np.rad2deg(speed.max()):.0f}°/s"
            if why is None and np.any(acc > amax):
                why = f"acceleration {np.rad2deg(acc.max()):.0f}°/s²"
            prev = [prev[-1], q]
        else:
            prev = []
        if why is not None:
            bad.append(
                f"{cmd}: {why} (after {before[:60]!r}; arm at {np.round(np.rad2deg(q_meas), 2).tolist()}, mode {mode})"
            )
        before = cmd
    return len(bad), n, bad[:3]


async def _fuzz(s, sim, requests: int = 120, clients: int = 4, seed: int = 0) -> None:  # type: ignore[no-untyped-def]
    """Concurrent random requests (some fast, some far, some out of limits, some NaN) from several
    gRPC clients at once through a recording proxy; every motion command on the wire is checked."""
    import grpc
    from pickplace.v1 import robot_pb2, robot_pb2_grpc

    from services.kinematics.interpolation import quintic_move
    from services.kinematics.robot_models import get_robot
    from services.kinematics.trajectory import JointLimits

    spec = get_robot(s.robot.model)
    rng = np.random.default_rng(seed)
    outcomes: dict[str, int] = {}
    async with RecordingProxy(sim.ports["dashboard"], sim.ports["feedback"]) as proxy:
        r = s.robot.model_copy(
            update={"dashboard_port": proxy.ports["dashboard"], "feedback_port": proxy.ports["feedback"]}
        )
        sp = s.model_copy(update={"robot": r})
        async with RobotService(sp, grpc_port=0) as svc, channel("127.0.0.1", svc.grpc_port) as ch:
            stub = robot_pb2_grpc.RobotControllerStub(ch)
            await stub.Enable(robot_pb2.EnableRequest())
            home = np.deg2rad([0.0, 0.0, 90.0, 0.0, -90.0, 0.0])
            left = iter(range(requests))

            async def one(k: int) -> None:
                q0 = np.array((await stub.GetJointStates(robot_pb2.GetJointStatesRequest())).position)
                kind = str(rng.choice(["traj", "traj", "traj", "far", "nan", "move", "move_out"]))
                goal = np.clip(q0 + rng.normal(0, 0.4, 6), spec.lower, spec.upper)
                scale = float(rng.choice([0.3, 1.0, 2.5]))  # 2.5× the limits: must be refused
                for _ in range(100):  # a busy refusal is retried: the others' motions take their time
                    if not await attempt(kind, q0, goal, scale):
                        break
                    await asyncio.sleep(0.1)  # (a real client waits its turn; hammering starves the driver)

            async def attempt(kind: str, q0: np.ndarray, goal: np.ndarray, scale: float) -> bool:
                """One request; True when it was refused as busy."""
                try:
                    if kind in ("traj", "far", "nan"):
                        lim = JointLimits.from_spec(spec, min(scale, 1.0), min(scale, 1.0))
                        tr = quintic_move(q0, goal, joint_names=spec.joint_names, limits=lim)
                        if scale > 1.0:
                            tr = type(tr)(
                                tr.joint_names,
                                tr.times / scale,
                                tr.positions,
                                tr.velocities * scale,
                                tr.accelerations * scale**2,
                            )
                        msg = tr.to_proto()
                        if kind == "far":
                            msg.points[0].positions[0] += 0.3
                        if kind == "nan":
                            msg.points[len(msg.points) // 2].positions[2] = float("nan")
                        await stub.ExecuteTrajectory(
                            robot_pb2.ExecuteTrajectoryRequest(trajectory=msg), timeout=60
                        )
                    else:
                        out = np.r_[0, 0, 0, 0, 0, 8.0 * rng.choice([-1, 1])]  # beyond joint 6's range
                        target = goal if kind == "move" else goal + out
                        await stub.MoveJoints(
                            robot_pb2.MoveJointsRequest(positions=target.tolist(), speed_ratio=100),
                            timeout=60,
                        )
                    outcomes["ok"] = outcomes.get("ok", 0) + 1
                except grpc.aio.AioRpcError as exc:
                    name = str(
                        dict(exc.trailing_metadata() or ()).get("pickplace-error-type", exc.code().name)
                    )
                    if name == "RobotBusyError":
                        return True
                    outcomes[name] = outcomes.get(name, 0) + 1
                    if name in ("ControllerError", "TrajectoryExecutionError", "ExecutionError"):
                        await stub.ClearError(robot_pb2.ClearErrorRequest())
                        await stub.Enable(robot_pb2.EnableRequest())
                return False

            async def client() -> None:
                for k in left:
                    await one(k)

            t0 = time.perf_counter()
            await asyncio.gather(*(client() for _ in range(clients)))
            wall = time.perf_counter() - t0
            await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=home.tolist(), speed_ratio=100))
        bad, n, examples = limit_violations(proxy.commands, svc.driver.limits)
    print(
        f"limits fuzz: {bad} violations / {requests} requests from {clients} concurrent gRPC clients "
        f"({n} motion commands on the wire, {wall:.1f} s); outcomes {dict(sorted(outcomes.items()))}"
    )
    for e in examples:
        print(f"  violation: {e}")


# ---------------------------------------------------------------------- link recovery
async def _recovery(s, sim, outages_s: tuple[float, ...] = (0.2, 1.0, 3.0), repeats: int = 3) -> None:  # type: ignore[no-untyped-def]
    """Cut the controller's network mid-motion for each outage; the controller-clock time from the
    network's return to sound feedback, and to the owed Stop at the controller."""
    from services.common.errors import RobotCommunicationError
    from services.common.settings import ReconnectSettings
    from services.dobot import RobotMode
    from services.robot.feedback import LinkEventKind, LinkState

    ctl = sim.controller
    back: list[float] = []
    stop: list[float] = []
    rs = ReconnectSettings(max_attempts=3, base_delay_s=0.05, max_delay_s=0.2)
    async with DobotClient("127.0.0.1", sim.ports["dashboard"], sim.ports["feedback"], reconnect=rs) as c:
        await c.enable()
        for outage in [o for o in outages_s for _ in range(repeats)]:
            await c.mov_j(np.deg2rad([60, 0, 90, 0, -90, 0]), v=5)
            await c.wait_feedback(lambda fb: fb.robot_mode == RobotMode.RUNNING, 2.0)
            n_events = len(c.link_events)
            await sim.cut_link()
            await asyncio.sleep(outage)  # the fault lasts this long
            with sim.lock:
                restored_ms, n_cmds = ctl.clock_ms, len(ctl.command_log)
            await sim.restore_link()
            async with asyncio.timeout(60):
                while not (c.link is LinkState.UP and not c.stop_owed):
                    with contextlib.suppress(RobotCommunicationError):
                        await c.next_feedback(0.5)
            up = next(e for e in list(c.link_events)[n_events:] if e.kind is LinkEventKind.RESTORED)
            back.append(float((up.stamp_ms or restored_ms) - restored_ms))
            with sim.lock:
                stop_ms = next(ms for ms, t in list(ctl.command_log)[n_cmds:] if t == "Stop()")
            stop.append(float(stop_ms - restored_ms))
            await c.wait_feedback(lambda fb: fb.robot_mode == RobotMode.ENABLE, 5.0)
            rid = await c.mov_j(np.deg2rad([0, 0, 90, 0, -90, 0]), v=100)
            await c.wait_motion_done(rid, 60.0)
    print(
        f"link recovery after outages {list(outages_s)} s (×{repeats}, controller clock from the network's "
        f"return): feedback back {_pct(back)}; owed Stop at the controller {_pct(stop)}"
    )


async def _safety() -> None:
    import logging

    # the faults are the point here: their warnings (links lost, trajectories refused) would drown the figures
    logging.getLogger("pickplace").setLevel(logging.CRITICAL)
    s = load_settings(
        "sim",
        overrides={
            "logging": {"file": None},
            "grpc": {"robot_port": 0},
            "robot": {"reconnect": {"max_attempts": 3, "base_delay_s": 0.05, "max_delay_s": 0.2}},
        },
    )
    async with build_sim_server(s, "kinematic", ports={"dashboard": 0, "feedback": 0, "slow": 0}) as sim:
        await _fuzz(s, sim)
    s1 = s.model_copy(update={"sim": s.sim.model_copy(update={"speed": 1.0})})
    async with build_sim_server(s1, "kinematic", ports={"dashboard": 0, "feedback": 0, "slow": 0}) as sim:
        await _recovery(s1, sim)


def main() -> None:
    asyncio.run(_run())
    asyncio.run(_safety())


if __name__ == "__main__":
    main()
