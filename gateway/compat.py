"""The LLD's ``robot_control.RobotController`` (§13.2) on the gateway's gRPC edge, beside pickplace.v1.

A client generated from the LLD's proto text (package ``robot_control``, its message and field names)
gets joint states, MoveJoints, ExecuteGrasp and StreamMetrics from the cell. Each call is translated
to the cell's own API and relayed to the robot driver (errors pass through with their status code and
pickplace error type), behind the same token as the rest of the edge.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from datetime import UTC, datetime

import grpc
import grpc.aio
from pickplace.v1 import common_pb2, robot_control_pb2, robot_control_pb2_grpc, robot_pb2, robot_pb2_grpc

from gateway.db.repository import PickRepository
from gateway.state import Cell

log = logging.getLogger("pickplace.gateway.compat")

METRICS_PERIOD_S = 1.0  # the LLD's StreamMetrics takes no period


def joint_states(js: common_pb2.JointState) -> robot_control_pb2.JointStates:
    return robot_control_pb2.JointStates(
        positions=list(js.position),
        velocities=list(js.velocity),
        efforts=list(js.effort),
        timestamp=js.source_stamp_ns or js.header.stamp_ns,
    )


def grasp_request(p: robot_control_pb2.GraspPose) -> robot_pb2.ExecuteGraspRequest:
    return robot_pb2.ExecuteGraspRequest(
        grasp_pose=common_pb2.Pose(x=p.x, y=p.y, z=p.z, qx=p.qx, qy=p.qy, qz=p.qz, qw=p.qw),
        approach_distance=p.approach_distance,
        lift_distance=p.lift_distance,
    )


class LldRobotController(robot_control_pb2_grpc.RobotControllerServicer):
    def __init__(self, cell: Cell, relay: robot_pb2_grpc.RobotControllerServicer):
        """``relay``: the edge's pickplace.v1 RobotController (it forwards to the robot driver)."""
        self._cell = cell
        self._relay = relay

    async def GetJointStates(
        self, request: robot_control_pb2.Empty, context: grpc.aio.ServicerContext
    ) -> robot_control_pb2.JointStates:
        js = await self._relay.GetJointStates(robot_pb2.GetJointStatesRequest(), context)
        return joint_states(js)

    async def MoveJoints(
        self, request: robot_control_pb2.JointPositions, context: grpc.aio.ServicerContext
    ) -> robot_control_pb2.MoveResponse:
        r = await self._relay.MoveJoints(
            robot_pb2.MoveJointsRequest(
                positions=list(request.positions),
                max_velocity=request.max_velocity,
                max_acceleration=request.max_acceleration,
            ),
            context,
        )
        return robot_control_pb2.MoveResponse(
            success=r.success, message=r.message, execution_time=r.execution_time
        )

    async def ExecuteGrasp(
        self, request: robot_control_pb2.GraspPose, context: grpc.aio.ServicerContext
    ) -> robot_control_pb2.GraspResponse:
        r = await self._relay.ExecuteGrasp(grasp_request(request), context)
        return robot_control_pb2.GraspResponse(
            success=r.success, message=r.message, object_detected=r.object_detected
        )

    async def StreamMetrics(
        self, request: robot_control_pb2.Empty, context: grpc.aio.ServicerContext
    ) -> AsyncIterator[robot_control_pb2.Metrics]:
        while True:
            sample = robot_control_pb2.Metrics()
            try:
                async with self._cell.sessions() as s:
                    summary = await PickRepository(s).summary(datetime.now(UTC))
                sample.cycle_time = summary.avg_cycle_time_s or 0.0
                sample.success_rate = summary.success_rate or 0.0
                sample.picks_today = summary.picks_today
            except Exception as exc:  # the stream goes on with what the snapshot knows
                log.debug("LLD metrics sample without database: %s", exc)
                sample.picks_today = self._cell.status.picks_today
            yield sample
            await asyncio.sleep(METRICS_PERIOD_S)
