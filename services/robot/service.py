"""The robot-driver service: RobotController over gRPC, joint states on Zenoh.

A thin shell: it builds the client/driver from settings, publishes every
feedback packet as a JointState on Zenoh (125 Hz), fans it out to gRPC
StreamJointStates subscribers, and maps RPCs onto :class:`RobotDriver`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Iterator

import grpc
import numpy as np
from pickplace.v1 import common_pb2, robot_pb2, robot_pb2_grpc

from services.common.bus import Bus
from services.common.frames import finite_vector
from services.common.keys import CellKeys
from services.common.live_config import LiveConfig
from services.common.messages import pose_to_matrix
from services.common.priority import favour_process
from services.common.settings import Settings
from services.common.settings.robot import RobotDriverKind
from services.common.shell import GrpcShell, cell_token
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_frame
from services.kinematics.trajectory import JointTrajectory
from services.robot.client import DobotClient
from services.robot.driver import RobotDriver
from services.robot.feedback import ClientState, FeedbackState, LinkState
from services.robot.guard import force_drop_condition, speed_up_length
from services.robot.link import ControllerLink
from services.robot.messages import joint_state_msg, robot_status_msg
from services.robot.safety import cap_ratio, speed_ratio_field
from services.robot.ur.link import URLink

log = logging.getLogger("pickplace.robot.service")

STREAM_QUEUE = 256
GUARD_BASELINE_PACKETS = 25  # 0.2 s at the 8 ms feedback period: let the arm settle, average the noise
FEEDBACK_STALE_TIMEOUTS = 5  # as DobotClient: a stream silent this many feedback timeouts is gone


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
    def subscription(self) -> Iterator[asyncio.Queue[common_pb2.JointState]]:
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

    async def GetJointStates(
        self, request: robot_pb2.GetJointStatesRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.JointState:
        return joint_state_msg(self.driver.feedback, self.driver.spec, self.hub.seq)

    async def GetStatus(
        self, request: robot_pb2.GetStatusRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.RobotStatus:
        fb = self.driver.client.feedback
        alarms: list[int] = []
        if fb is not None and fb.in_error:
            alarms, _ = await self.driver.client.describe_alarms()
        return robot_status_msg(
            fb, self.driver.spec, fb is not None, alarms, self.driver.gripper.state().closed
        )

    async def MoveJoints(
        self, request: robot_pb2.MoveJointsRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.MoveResponse:
        q = finite_vector(list(request.positions), self.driver.spec.dof, "positions")
        spec = self.driver.spec
        # every field is honoured or refused, never ignored: the caps become the controller's ratios
        ratios = [
            r
            for r in (
                speed_ratio_field(request.speed_ratio),
                cap_ratio(request.max_velocity, spec.max_velocity, "max_velocity", "rad/s"),
            )
            if r is not None
        ]
        acc = cap_ratio(request.max_acceleration, spec.max_acceleration, "max_acceleration", "rad/s²")
        res = await self.driver.move_joints(
            q, min(ratios) if ratios else None, linear=request.linear, acceleration_ratio=acc
        )
        return robot_pb2.MoveResponse(
            success=True,
            message=f"reached in {res.attempts} attempt(s)",
            execution_time=res.duration_s,
            final_positions=res.final_q.tolist(),
        )

    async def ExecuteTrajectory(
        self, request: robot_pb2.ExecuteTrajectoryRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.MoveResponse:
        traj = JointTrajectory.from_proto(request.trajectory)
        stop_when = None
        if request.HasField("force_guard") and request.force_guard.force_drop_n > 0:
            baseline = await self._settled_wrench()
            direction = list(request.force_guard.direction)
            tool = self.driver.limits.tool_positions(traj.positions)
            stop_when = force_drop_condition(
                baseline,
                request.force_guard.force_drop_n,
                direction,
                arm_after_m=speed_up_length(tool, traj.times, direction),
            )
        res = await self.driver.execute_trajectory(
            traj, request.servo_period_s or None, stop_when, continues=request.continues
        )
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

    async def StreamJointStates(
        self, request: robot_pb2.StreamJointStatesRequest, context: grpc.aio.ServicerContext
    ) -> AsyncIterator[common_pb2.JointState]:
        min_interval_ns = int(1e9 / request.max_rate_hz) if request.max_rate_hz > 0 else 0
        last_ns = 0
        with self.hub.subscription() as q:
            while True:
                msg = await q.get()
                if min_interval_ns and msg.header.stamp_ns - last_ns < min_interval_ns:
                    continue
                last_ns = msg.header.stamp_ns
                yield msg

    async def SetGripper(
        self, request: robot_pb2.SetGripperRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.GripperResponse:
        st = await self.driver.set_gripper(request.close, release=request.release)
        return robot_pb2.GripperResponse(
            success=True,
            closed=st.closed,
            object_detected=bool(st.object_detected),
            message=("already " if st.unchanged else "") + ("closed" if st.closed else "open"),
            unchanged=st.unchanged,
        )

    async def ExecuteGrasp(
        self, request: robot_pb2.ExecuteGraspRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.GripperResponse:
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

    async def Stop(
        self, request: robot_pb2.StopRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        await self.driver.stop()
        return common_pb2.CommandResponse(success=True, message="stopped")

    async def EmergencyStop(
        self, request: robot_pb2.EmergencyStopRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        await self.driver.emergency_stop(release=request.release)
        return common_pb2.CommandResponse(
            success=True, message="e-stop released" if request.release else "e-stop pressed"
        )

    async def ClearError(
        self, request: robot_pb2.ClearErrorRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        await self.driver.clear_error()
        return common_pb2.CommandResponse(success=True, message="alarms cleared")

    async def Enable(
        self, request: robot_pb2.EnableRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        await self.driver.enable()
        return common_pb2.CommandResponse(success=True, message="enabled")

    async def Disable(
        self, request: robot_pb2.DisableRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        await self.driver.disable()
        return common_pb2.CommandResponse(success=True, message="disabled")


def build_driver(settings: Settings) -> RobotDriver:
    r = settings.robot
    client: ControllerLink
    if r.driver is RobotDriverKind.UR_RTDE:
        client = URLink(
            r.host,
            get_robot(r.model),
            request_timeout_s=r.request_timeout_s,
            feedback_timeout_s=r.feedback_timeout_s,
            reconnect=r.reconnect,
        )
        return RobotDriver(client, get_robot(r.model), settings, tool_frame(settings))
    client = DobotClient(
        r.host,
        r.dashboard_port,
        r.feedback_port,
        request_timeout_s=r.request_timeout_s,
        connect_timeout_s=r.connect_timeout_s,
        feedback_timeout_s=r.feedback_timeout_s,
        reconnect=r.reconnect,
    )
    return RobotDriver(client, get_robot(r.model), settings, tool_frame(settings))


def robot_link_up(client: ControllerLink, feedback_timeout_s: float, now_ns: int) -> bool:
    """The controller link is up while feedback keeps arriving: the packet stream is the controller's
    heartbeat (8 ms); the client gives up a silent stream after the same five feedback timeouts."""
    fb = client.feedback
    if client.state is ClientState.CLOSED or client.link is not LinkState.UP or fb is None:
        return False
    return now_ns - fb.received_ns < FEEDBACK_STALE_TIMEOUTS * max(feedback_timeout_s, 0.05) * 1e9


class RobotService(GrpcShell):
    """Owns the driver, the gRPC server and the Zenoh publisher for one robot."""

    kind = "robot"

    def __init__(self, settings: Settings, bus: Bus | None = None, grpc_port: int | None = None):
        super().__init__(
            settings.grpc.host,
            settings.grpc.robot_port if grpc_port is None else grpc_port,
            cell_token(settings),
        )
        self.settings = settings
        self.driver = build_driver(settings)
        self.bus = bus
        self.hub = JointStateHub(self.driver, bus, CellKeys(settings.cell_id))
        self.live: LiveConfig | None = None

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        client = self.driver.client
        stack.push_async_callback(client.close)
        stack.push_async_callback(self.driver.close)
        await self.driver.start()
        client.add_listener(self.hub.on_feedback)
        stack.callback(client.remove_listener, self.hub.on_feedback)
        servicer = RobotControllerServicer(self.driver, self.hub)
        await self._serve_grpc(
            stack,
            lambda server: robot_pb2_grpc.add_RobotControllerServicer_to_server(servicer, server),
            "RobotController",
        )
        if self.bus is not None:
            self.live = self.follow_config(self.bus, self.settings, self._on_config)

    def links(self) -> dict[str, bool]:
        up = robot_link_up(self.driver.client, self.settings.robot.feedback_timeout_s, time.time_ns())
        return {"robot controller": up}

    async def _on_config(self, new: Settings, changed: list[str]) -> None:
        self.settings = new
        await self.driver.update_settings(new, changed)


async def serve(settings: Settings) -> None:
    """``pickplace serve robot``: run until cancelled."""
    favour_process(settings.robot.process_nice, "the robot driver's process")
    async with Bus(settings.zenoh) as bus, RobotService(settings, bus) as svc:
        await svc.wait()
