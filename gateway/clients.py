"""gRPC clients of the gateway: the task service (start/stop) and the robot driver (status, e-stop).

The e-stop goes over its own channel to the robot driver, opened at start and kept, so it is
never queued behind a status poll or a slow task call; the task service is told as well, best
effort, without the e-stop waiting for it.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable
from typing import Any

import grpc
import grpc.aio
from pickplace.v1 import common_pb2, robot_pb2, robot_pb2_grpc, task_pb2, task_pb2_grpc

from services.common.errors import RobotCommunicationError
from services.common.grpc_util import bearer_metadata, cell_token, channel, translate
from services.common.settings import Settings
from services.common.shell import ServiceShell

log = logging.getLogger("pickplace.gateway.clients")

UNREACHABLE = (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED)


# Reconnect quickly after a service restarts (gRPC's default backoff starts at 1 s and grows to 120 s).
CHANNEL_OPTIONS = [
    ("grpc.initial_reconnect_backoff_ms", 100),
    ("grpc.min_reconnect_backoff_ms", 100),
    ("grpc.max_reconnect_backoff_ms", 1000),
]


def open_channel(host: str, port: int, token: str | None = None) -> grpc.aio.Channel:
    """A channel to a cell service; with the cell's token (gateway.api_token) on every call."""
    return channel(host, port, token, CHANNEL_OPTIONS)


@contextlib.contextmanager
def _relay_errors(
    service: str, target: str, ch: grpc.aio.Channel | None = None, timeout_s: float = 0.0
) -> Any:
    """Map gRPC failures to pickplace errors; an unreachable service is named with its address."""
    try:
        yield
    except grpc.RpcError as exc:
        err = translate(exc)
        code = exc.code() if hasattr(exc, "code") else None
        if code in UNREACHABLE and isinstance(err, RobotCommunicationError):
            connected = ch is not None and ch.get_state() == grpc.ChannelConnectivity.READY
            if code == grpc.StatusCode.DEADLINE_EXCEEDED and connected:
                raise RobotCommunicationError(
                    f"{service} at {target} did not answer within {timeout_s:g} s"
                ) from exc
            raise RobotCommunicationError(
                f"{service} unreachable at {target} ({code.name}: {exc.details()})"
            ) from exc
        raise err from exc


class CellClients(ServiceShell):
    """Channels and stubs, as a shell: the e-stop's task-service notification runs in its task group."""

    kind = "gateway-clients"

    def __init__(self, settings: Settings):
        super().__init__()
        g = settings.grpc
        self.timeout_s = settings.gateway.rpc_timeout_s
        self.estop_timeout_s = settings.gateway.estop_timeout_s
        self._task_host, self._robot_host = g.client_host("task"), g.client_host("robot")
        self.task_target = f"{self._task_host}:{g.task_port}"
        self.robot_target = f"{self._robot_host}:{g.robot_port}"
        self._task_port = g.task_port
        self._robot_port = g.robot_port
        self._channels: list[grpc.aio.Channel] = []
        self._token = cell_token(settings)
        # the e-stop's channel has no interceptor: its calls carry the token themselves
        self.estop_metadata = bearer_metadata(self._token) if self._token else None
        self.task: task_pb2_grpc.TaskControllerStub | None = None
        self.robot: robot_pb2_grpc.RobotControllerStub | None = None
        self.estop_robot: robot_pb2_grpc.RobotControllerStub | None = None
        self.estop_task: task_pb2_grpc.TaskControllerStub | None = None

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        # a task-service notification still waiting at shutdown is moot: the shell cancels it first
        stack.push_async_callback(self._close_channels)

        def open_(host: str, port: int, token: str | None = self._token) -> grpc.aio.Channel:
            ch = open_channel(host, port, token)
            self._channels.append(ch)
            return ch

        self.task_channel = open_(self._task_host, self._task_port)
        self.robot_channel = open_(self._robot_host, self._robot_port)
        # no client interceptor on the e-stop's channel (each adds a task and loop turns before the
        # request leaves): its calls carry the token as their own metadata (estop_metadata)
        self.estop_channel = open_(self._robot_host, self._robot_port, None)
        self.task = task_pb2_grpc.TaskControllerStub(self.task_channel)
        self.robot = robot_pb2_grpc.RobotControllerStub(self.robot_channel)
        self.estop_robot = robot_pb2_grpc.RobotControllerStub(self.estop_channel)
        self.estop_task = task_pb2_grpc.TaskControllerStub(open_(self._task_host, self._task_port))
        # connect the e-stop channel now, so the first e-stop does not pay the TCP/HTTP2 handshake
        self.estop_channel.get_state(try_to_connect=True)

    async def _close_channels(self) -> None:
        for ch in self._channels:
            await ch.close()
        self._channels.clear()

    # ---------------------------------------------------------------- task service
    async def start_task(self, task: str, cycles: int) -> common_pb2.CommandResponse:
        assert self.task is not None
        with _relay_errors("task service", self.task_target, self.task_channel, self.timeout_s):
            return await self.task.Start(
                task_pb2.StartTaskRequest(task=task, cycles=cycles),
                timeout=self.timeout_s,
                wait_for_ready=True,
            )

    async def stop_task(self) -> common_pb2.CommandResponse:
        assert self.task is not None
        with _relay_errors("task service", self.task_target, self.task_channel, self.timeout_s):
            return await self.task.Stop(
                task_pb2.StopTaskRequest(), timeout=self.timeout_s, wait_for_ready=True
            )

    async def task_status(self, wait_for_ready: bool = False) -> task_pb2.TaskStatus:
        """``wait_for_ready``: before a command, wait (up to the timeout) for a channel still
        backing off after a restart, as the command itself would."""
        assert self.task is not None
        with _relay_errors("task service", self.task_target, self.task_channel, self.timeout_s):
            return await self.task.GetStatus(
                task_pb2.GetTaskStatusRequest(), timeout=self.timeout_s, wait_for_ready=wait_for_ready
            )

    # ---------------------------------------------------------------- robot driver
    async def robot_status(self) -> robot_pb2.RobotStatus:
        assert self.robot is not None
        with _relay_errors("robot driver", self.robot_target):
            return await self.robot.GetStatus(robot_pb2.GetStatusRequest(), timeout=self.timeout_s)

    async def emergency_stop(
        self, on_task_result: Callable[[str], None] | None = None
    ) -> common_pb2.CommandResponse:
        """Press the e-stop on the robot driver; tell the task service in the background."""
        assert self.estop_robot is not None
        with _relay_errors("robot driver", self.robot_target, self.estop_channel, self.estop_timeout_s):
            # the driver's call is under way first; the task's notification is spawned behind it.
            # wait_for_ready: a channel still backing off after a driver restart waits (up to the
            # timeout) for the reconnection instead of failing at once
            call = self.estop_robot.EmergencyStop(
                robot_pb2.EmergencyStopRequest(),
                timeout=self.estop_timeout_s,
                wait_for_ready=True,
                metadata=self.estop_metadata,
            )
            self.spawn(self._notify_task_estop(on_task_result), "estop-task-notify")
            return await call

    async def _notify_task_estop(self, on_result: Callable[[str], None] | None) -> None:
        assert self.estop_task is not None
        try:
            with _relay_errors("task service", self.task_target):
                await self.estop_task.EmergencyStop(
                    task_pb2.TaskEmergencyStopRequest(), timeout=self.timeout_s, wait_for_ready=True
                )
            result = "task service notified"
        except Exception as exc:  # best effort, the job's boundary: the e-stop itself went on its own channel
            result = f"task service not notified: {exc}"
            log.info(result)
        if on_result is not None:
            on_result(result)

    async def release_estop(self) -> None:
        """Release the software e-stop, clear the alarms and enable the arm again."""
        assert self.robot is not None
        with _relay_errors("robot driver", self.robot_target):
            await self.robot.EmergencyStop(
                robot_pb2.EmergencyStopRequest(release=True), timeout=self.timeout_s
            )
            await self.robot.ClearError(robot_pb2.ClearErrorRequest(), timeout=self.timeout_s)
            await self.robot.Enable(robot_pb2.EnableRequest(), timeout=self.timeout_s * 3)
