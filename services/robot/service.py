"""The robot-driver service: RobotController over gRPC, joint states on Zenoh.

A thin shell: it builds the client/driver from settings, publishes every
feedback packet as a JointState on Zenoh (125 Hz), fans it out to gRPC
StreamJointStates subscribers, and maps RPCs onto :class:`RobotDriver`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator

import grpc
import numpy as np
from pickplace.v1 import common_pb2, robot_pb2, robot_pb2_grpc

from services.common import grpc_util
from services.common.bus import Bus
from services.common.errors import InvalidInputError
from services.common.frames import finite_vector
from services.common.keys import CellKeys
from services.common.live_config import LiveConfig
from services.common.messages import pose_to_matrix
from services.common.settings import Settings
from services.kinematics.robot_models import get_robot
from services.kinematics.trajectory import JointTrajectory
from services.robot.client import DobotClient, FeedbackState
from services.robot.driver import RobotDriver
from services.robot.messages import joint_state_msg, robot_status_msg

log = logging.getLogger("pickplace.robot.service")

STREAM_QUEUE = 256
GUARD_DEBOUNCE_PACKETS = 3  # 24 ms of sustained force change = touch-down
GUARD_BASELINE_PACKETS = 25  # 0.2 s at the 8 ms feedback period: let the arm settle, average the noise


class JointStateHub:
    """Fans every feedback packet out to Zenoh and to per-stream queues (newest wins)."""

    def __init__(self, driver: RobotDriver, bus: Bus | None, keys: CellKeys):
        self._driver = driver
        self._bus = bus
        self._keys = keys
        self._queues: set[asyncio.Queue[common_pb2.JointState]] = set()
        self.seq = 0
        self.published = 0

    def on_feedback(self, fb: FeedbackState) -> None:
        self.seq += 1
        msg = joint_state_msg(fb, self._driver.spec, self.seq)
        if self._bus is not None:
            try:
                self._bus.publish(self._keys.joint_states, msg)
                self.published += 1
            except Exception as exc:  # the bus must never break the feedback loop
                log.warning("zenoh publish failed: %s", exc)
        for q in list(self._queues):
            if q.full():
                q.get_nowait()
            q.put_nowait(msg)

    @contextlib.contextmanager
    def subscription(self) -> AsyncIterator[asyncio.Queue[common_pb2.JointState]]:  # type: ignore[misc]
        q: asyncio.Queue[common_pb2.JointState] = asyncio.Queue(STREAM_QUEUE)
        self._queues.add(q)
        try:
            yield q
        finally:
            self._queues.discard(q)


class RobotControllerServicer(robot_pb2_grpc.RobotControllerServicer):
    def __init__(self, driver: RobotDriver, hub: JointStateHub):
        self.driver = driver
        self.hub = hub

    async def GetJointStates(self, request, context):  # type: ignore[no-untyped-def]
        return joint_state_msg(self.driver.feedback, self.driver.spec, self.hub.seq)

    async def GetStatus(self, request, context):  # type: ignore[no-untyped-def]
        fb = self.driver.client.feedback
        alarms: list[int] = []
        if fb is not None and fb.in_error:
            alarms, _ = await self.driver.client.describe_alarms()
        return robot_status_msg(
            fb, self.driver.spec, fb is not None, alarms, self.driver.gripper.state().closed
        )

    async def MoveJoints(self, request, context):  # type: ignore[no-untyped-def]
        q = finite_vector(list(request.positions), self.driver.spec.dof, "positions")
        ratio = int(request.speed_ratio) if request.speed_ratio else None
        res = await self.driver.move_joints(q, ratio, linear=request.linear)
        return robot_pb2.MoveResponse(
            success=True,
            message=f"reached in {res.attempts} attempt(s)",
            execution_time=res.duration_s,
            final_positions=res.final_q.tolist(),
        )

    async def ExecuteTrajectory(self, request, context):  # type: ignore[no-untyped-def]
        traj = JointTrajectory.from_proto(request.trajectory)
        stop_when = None
        if request.HasField("force_guard") and request.force_guard.force_drop_n > 0:
            baseline = await self._settled_wrench()
            stop_when = force_drop_condition(
                baseline, request.force_guard.force_drop_n, list(request.force_guard.direction)
            )
        res = await self.driver.execute_trajectory(traj, request.servo_period_s or None, stop_when)
        return robot_pb2.MoveResponse(
            success=True,
            message=f"{len(traj)} points executed" + (" (stopped on force)" if res.stopped_early else ""),
            execution_time=res.duration_s,
            final_positions=res.final_q.tolist(),
            stopped_early=res.stopped_early,
        )

    async def _settled_wrench(self, packets: int = GUARD_BASELINE_PACKETS) -> np.ndarray:
        """The wrist wrench averaged over a few packets at rest: the guarded move's reference."""
        samples = [(await self.driver.client.next_feedback()).tcp_force for _ in range(packets)]
        return np.mean(samples, axis=0)

    async def StreamJointStates(self, request, context):  # type: ignore[no-untyped-def]
        min_interval_ns = int(1e9 / request.max_rate_hz) if request.max_rate_hz > 0 else 0
        last_ns = 0
        with self.hub.subscription() as q:
            while True:
                msg = await q.get()
                if min_interval_ns and msg.header.stamp_ns - last_ns < min_interval_ns:
                    continue
                last_ns = msg.header.stamp_ns
                yield msg

    async def SetGripper(self, request, context):  # type: ignore[no-untyped-def]
        st = await self.driver.set_gripper(request.close)
        return robot_pb2.GripperResponse(
            success=True,
            closed=st.closed,
            object_detected=bool(st.object_detected),
            message="closed" if st.closed else "open",
        )

    async def ExecuteGrasp(self, request, context):  # type: ignore[no-untyped-def]
        T = pose_to_matrix(request.grasp_pose, "grasp_pose")
        st = await self.driver.execute_grasp(
            T, request.approach_distance or 0.10, request.lift_distance or 0.10, request.speed_scale or 0.3
        )
        return robot_pb2.GripperResponse(
            success=True,
            closed=st.closed,
            object_detected=bool(st.object_detected),
            message="grasped and lifted",
        )

    async def Stop(self, request, context):  # type: ignore[no-untyped-def]
        await self.driver.stop()
        return common_pb2.CommandResponse(success=True, message="stopped")

    async def EmergencyStop(self, request, context):  # type: ignore[no-untyped-def]
        await self.driver.emergency_stop(release=request.release)
        return common_pb2.CommandResponse(
            success=True, message="e-stop released" if request.release else "e-stop pressed"
        )

    async def ClearError(self, request, context):  # type: ignore[no-untyped-def]
        await self.driver.clear_error()
        return common_pb2.CommandResponse(success=True, message="alarms cleared")

    async def Enable(self, request, context):  # type: ignore[no-untyped-def]
        await self.driver.enable()
        return common_pb2.CommandResponse(success=True, message="enabled")

    async def Disable(self, request, context):  # type: ignore[no-untyped-def]
        await self.driver.disable()
        return common_pb2.CommandResponse(success=True, message="disabled")


def force_drop_condition(baseline_wrench: np.ndarray, drop_n: float, direction: list[float]):  # type: ignore[no-untyped-def]
    """Stop condition of a guarded move: the force along ``direction`` fell by ``drop_n``."""
    d = finite_vector(direction or [0.0, 0.0, -1.0], 3, "force guard direction")
    norm = float(np.linalg.norm(d))
    if norm < 1e-9 or not np.isfinite(drop_n) or drop_n <= 0:
        raise InvalidInputError(
            f"force guard needs a direction and a positive force drop, got {direction}, {drop_n}"
        )
    d = d / norm
    start = float(np.dot(baseline_wrench[:3], d))
    run = 0

    def fired(fb: FeedbackState) -> bool:
        # debounced: a contact holds for several packets, a jolt of the arm does not
        nonlocal run
        run = run + 1 if start - float(np.dot(fb.tcp_force[:3], d)) > drop_n else 0
        return run >= GUARD_DEBOUNCE_PACKETS

    return fired


def build_driver(settings: Settings) -> RobotDriver:
    r = settings.robot
    client = DobotClient(
        r.host,
        r.dashboard_port,
        r.feedback_port,
        request_timeout_s=r.request_timeout_s,
        connect_timeout_s=r.connect_timeout_s,
        feedback_timeout_s=r.feedback_timeout_s,
        reconnect=r.reconnect,
    )
    T_flange_tool = np.eye(4)
    T_flange_tool[2, 3] = settings.gripper.tcp_offset_m  # the grasp centre, along the flange z axis
    return RobotDriver(client, get_robot(r.model), settings, T_flange_tool)


class RobotService:
    """Owns the driver, the gRPC server and the Zenoh publisher for one robot."""

    def __init__(self, settings: Settings, bus: Bus | None = None, grpc_port: int | None = None):
        self.settings = settings
        self.driver = build_driver(settings)
        self.bus = bus
        self.hub = JointStateHub(self.driver, bus, CellKeys(settings.cell_id))
        self.server: grpc.aio.Server | None = None
        self.grpc_port = settings.grpc.robot_port if grpc_port is None else grpc_port
        self.live: LiveConfig | None = None

    async def start(self) -> int:
        await self.driver.start()
        self.driver.client.add_listener(self.hub.on_feedback)
        self.server = grpc_util.create_server()
        robot_pb2_grpc.add_RobotControllerServicer_to_server(
            RobotControllerServicer(self.driver, self.hub), self.server
        )
        self.grpc_port = grpc_util.bind(self.server, self.settings.grpc.host, self.grpc_port)
        await self.server.start()
        if self.bus is not None:
            self.live = LiveConfig(self.bus, self.settings, self._on_config).start()
        log.info("robot driver serving RobotController on %s:%d", self.settings.grpc.host, self.grpc_port)
        return self.grpc_port

    async def _on_config(self, new: Settings, changed: list[str]) -> None:
        self.settings = new
        await self.driver.update_settings(new, changed)

    async def stop(self) -> None:
        if self.live is not None:
            await self.live.stop()
            self.live = None
        if self.server is not None:
            await self.server.stop(grace=0.5)
            self.server = None
        self.driver.client.remove_listener(self.hub.on_feedback)
        await self.driver.client.close()

    async def __aenter__(self) -> RobotService:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()


async def serve(settings: Settings) -> None:
    """``pickplace serve robot``: run until cancelled."""
    async with Bus(settings.zenoh) as bus, RobotService(settings, bus) as svc:
        assert svc.server is not None
        await svc.server.wait_for_termination()
