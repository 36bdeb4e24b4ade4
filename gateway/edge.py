"""The gateway's gRPC edge (LLD §13.2) for clients outside the cell.

It serves the ``RobotController`` of ``robot.proto`` by relaying each call to the robot driver
(GetJointStates, MoveJoints, StreamJointStates, …; EmergencyStop on the gateway's own e-stop
channel), and ``CellMetrics.StreamMetrics`` of ``gateway.proto``. Every call needs the gateway's
token in its metadata: ``authorization: Bearer <token>``; without it, UNAUTHENTICATED.
Errors from the driver pass through with their status code and pickplace error type.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from datetime import UTC, datetime
from typing import Any, NoReturn, TypeVar

import grpc
import grpc.aio
from google.protobuf.message import Message
from pickplace.v1 import common_pb2, gateway_pb2, gateway_pb2_grpc, robot_pb2, robot_pb2_grpc

from gateway.db.repository import PickRepository
from gateway.security import bearer_from_header, token_matches
from gateway.state import Cell
from services.common import grpc_util
from services.common.shell import GrpcShell

R = TypeVar("R")

log = logging.getLogger("pickplace.gateway.edge")


class TokenAuthInterceptor(grpc.aio.ServerInterceptor):
    def __init__(self, token: str):
        self._token = token

    async def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], Awaitable[grpc.RpcMethodHandler[Any, Any] | None]],
        details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler[Any, Any] | None:
        handler = await continuation(details)
        metadata = {k: str(v) for k, v in (details.invocation_metadata or ())}
        presented = bearer_from_header(metadata.get("authorization"))
        if handler is None or token_matches(presented, self._token):
            return handler
        message = (
            "missing 'authorization: Bearer <token>' metadata"
            if presented is None
            else "bearer token is not valid"
        )

        return grpc_util.unauthenticated_handler(handler, message)


async def _passthrough(context: grpc.aio.ServicerContext, exc: grpc.aio.AioRpcError) -> NoReturn:
    md = exc.trailing_metadata() or ()
    kind = next((v for k, v in md if k == grpc_util.ERROR_TYPE_KEY), None)
    if kind is not None:
        context.set_trailing_metadata(((grpc_util.ERROR_TYPE_KEY, str(kind)),))
    await context.abort(exc.code(), exc.details() or "")


class RobotControllerRelay(robot_pb2_grpc.RobotControllerServicer):
    """Each RPC forwarded to the robot driver with the caller's deadline (capped)."""

    def __init__(self, cell: Cell, max_timeout_s: float = 120.0):
        self._cell = cell
        self._max_timeout_s = max_timeout_s

    def _timeout(self, context: grpc.aio.ServicerContext) -> float:
        remaining = context.time_remaining()
        return min(remaining, self._max_timeout_s) if remaining is not None else self._max_timeout_s

    def _stub(self, estop: bool = False) -> robot_pb2_grpc.RobotControllerStub:
        clients = self._cell.clients
        stub = clients.estop_robot if estop else clients.robot
        assert stub is not None, "the gateway's clients are open while the edge serves"
        return stub

    async def _relay(
        self,
        method: Callable[..., Awaitable[R]],
        request: Message,
        context: grpc.aio.ServicerContext,
        estop: bool = False,
    ) -> R:
        try:
            return await method(
                request,
                timeout=self._timeout(context),
                wait_for_ready=estop,
                metadata=self._cell.clients.estop_metadata if estop else None,
            )
        except grpc.aio.AioRpcError as exc:
            await _passthrough(context, exc)

    async def GetJointStates(
        self, request: robot_pb2.GetJointStatesRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.JointState:
        return await self._relay(self._stub().GetJointStates, request, context)

    async def GetStatus(
        self, request: robot_pb2.GetStatusRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.RobotStatus:
        return await self._relay(self._stub().GetStatus, request, context)

    async def MoveJoints(
        self, request: robot_pb2.MoveJointsRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.MoveResponse:
        return await self._relay(self._stub().MoveJoints, request, context)

    async def ExecuteTrajectory(
        self, request: robot_pb2.ExecuteTrajectoryRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.MoveResponse:
        return await self._relay(self._stub().ExecuteTrajectory, request, context)

    async def ExecuteGrasp(
        self, request: robot_pb2.ExecuteGraspRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.GripperResponse:
        return await self._relay(self._stub().ExecuteGrasp, request, context)

    async def SetGripper(
        self, request: robot_pb2.SetGripperRequest, context: grpc.aio.ServicerContext
    ) -> robot_pb2.GripperResponse:
        return await self._relay(self._stub().SetGripper, request, context)

    async def Stop(
        self, request: robot_pb2.StopRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        return await self._relay(self._stub().Stop, request, context)

    async def EmergencyStop(
        self, request: robot_pb2.EmergencyStopRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        if not request.release:
            self._cell.metrics.estop.labels(self._cell.robot_id, "grpc").inc()
        return await self._relay(self._stub(estop=True).EmergencyStop, request, context, estop=True)

    async def ClearError(
        self, request: robot_pb2.ClearErrorRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        return await self._relay(self._stub().ClearError, request, context)

    async def Enable(
        self, request: robot_pb2.EnableRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        return await self._relay(self._stub().Enable, request, context)

    async def Disable(
        self, request: robot_pb2.DisableRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        return await self._relay(self._stub().Disable, request, context)

    async def StreamJointStates(
        self, request: robot_pb2.StreamJointStatesRequest, context: grpc.aio.ServicerContext
    ) -> AsyncIterator[common_pb2.JointState]:
        call = self._stub().StreamJointStates(request)
        try:
            async for msg in call:
                yield msg
        except grpc.aio.AioRpcError as exc:
            await _passthrough(context, exc)
        finally:
            call.cancel()


class CellMetricsServicer(gateway_pb2_grpc.CellMetricsServicer):
    def __init__(self, cell: Cell, status: Callable[[], Awaitable[str]]):
        self._cell = cell
        self._status = status

    async def StreamMetrics(
        self, request: gateway_pb2.StreamMetricsRequest, context: grpc.aio.ServicerContext
    ) -> AsyncIterator[gateway_pb2.MetricsSample]:
        period = max(request.period_s or 1.0, 0.1)
        seq = 0
        while True:
            seq += 1
            sample = gateway_pb2.MetricsSample(
                header=common_pb2.Header(stamp_ns=time.time_ns(), seq=seq),
                state=await self._status(),
                database_ok=self._cell.writer.database_ok,
            )
            try:
                async with self._cell.sessions() as s:
                    summary = await PickRepository(s).summary(datetime.now(UTC))
                sample.cycle_time = summary.avg_cycle_time_s or 0.0
                sample.success_rate = summary.success_rate or 0.0
                sample.picks_today = summary.picks_today
                sample.picks_total = summary.total
            except Exception as exc:  # the stream goes on; database_ok tells the client
                log.debug("metrics sample without database: %s", exc)
                sample.database_ok = False
            yield sample
            await asyncio.sleep(period)


class EdgeServer(GrpcShell):
    """The edge's gRPC server (RobotController relay, CellMetrics), every call behind the token."""

    kind = "gateway-edge"

    def __init__(self, cell: Cell, host: str, port: int, token: str, status: Callable[[], str]):
        """``status``: the cell's state as ``GET /system/status`` names it (for MetricsSample.state)."""
        super().__init__(host, port)
        self._cell = cell
        self._token = token
        self._status = status

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        async def state() -> str:
            return self._status()

        from pickplace.v1 import robot_control_pb2_grpc

        from gateway.compat import LldRobotController  # the LLD's names, relayed the same way

        def register(server: grpc.aio.Server) -> None:
            relay = RobotControllerRelay(self._cell)
            robot_pb2_grpc.add_RobotControllerServicer_to_server(relay, server)
            gateway_pb2_grpc.add_CellMetricsServicer_to_server(CellMetricsServicer(self._cell, state), server)
            robot_control_pb2_grpc.add_RobotControllerServicer_to_server(
                LldRobotController(self._cell, relay), server
            )

        await self._serve_grpc(
            stack,
            register,
            "the gRPC edge (RobotController, CellMetrics, robot_control.RobotController)",
            [TokenAuthInterceptor(self._token)],
        )
