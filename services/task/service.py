"""The task service: TaskController over gRPC and the status ticker around a :class:`TaskRunner`
(:mod:`services.task.runner`: the cycle loop, its records and status on Zenoh). Cycle and stage times
are on the controller's clock: the composition root may pass it in (the in-process cell reads the
driver's feedback); otherwise the service follows the TimeStamp of the robot's joint states on the bus.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable

import grpc
from pickplace.v1 import common_pb2, task_pb2, task_pb2_grpc

from services.common.bus import Bus
from services.common.errors import InvalidInputError
from services.common.keys import CellKeys
from services.common.settings import Settings
from services.common.shell import GrpcShell, cell_token
from services.task.clients import CellClients
from services.task.journal import CycleJournal
from services.task.messages import pick_event_msg
from services.task.runner import TaskRunner, journal_path

log = logging.getLogger("pickplace.task.service")


class ControllerClock:
    """The controller's clock as the task sees it (s): the TimeStamp of the newest robot joint state
    on the bus. Before the first one arrives it reads the wall clock (said once in the log)."""

    def __init__(self) -> None:
        self._stamp_ns: int | None = None
        self._warned = False

    def observe(self, stamp_ns: int) -> None:
        if stamp_ns > 0:
            self._stamp_ns = stamp_ns

    def on_joint_state(self, _key: str, payload: bytes) -> None:
        msg = common_pb2.JointState()
        msg.ParseFromString(payload)
        self.observe(msg.source_stamp_ns)

    def __call__(self) -> float:
        if self._stamp_ns is None:
            if not self._warned:
                self._warned = True
                log.warning("no robot joint state yet: cycle times read the wall clock until one arrives")
            return time.time()
        return self._stamp_ns / 1e9


class TaskControllerServicer(task_pb2_grpc.TaskControllerServicer):
    def __init__(self, runner: TaskRunner):
        self.runner = runner

    async def Start(
        self, request: task_pb2.StartTaskRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        if request.cycles < 0:
            raise InvalidInputError(f"cycles must be >= 0, got {request.cycles}")
        self.runner.start(request.task or None, request.cycles)
        return common_pb2.CommandResponse(success=True, message=f"started {self.runner.task}")

    async def Stop(
        self, request: task_pb2.StopTaskRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        await self.runner.stop()
        return common_pb2.CommandResponse(success=True, message="stopped")

    async def EmergencyStop(
        self, request: task_pb2.TaskEmergencyStopRequest, context: grpc.aio.ServicerContext
    ) -> common_pb2.CommandResponse:
        await self.runner.emergency_stop()
        return common_pb2.CommandResponse(success=True, message="emergency stop pressed")

    async def RunSingleCycle(
        self, request: task_pb2.SingleCycleRequest, context: grpc.aio.ServicerContext
    ) -> task_pb2.PickEvent:
        if self.runner.running:
            raise InvalidInputError("the task loop is running; stop it before a single cycle")
        outcome = await self.runner.run_cycle(request.task or None)
        return pick_event_msg(outcome, self.runner.settings.cell_id)

    async def GetStatus(
        self, request: task_pb2.GetTaskStatusRequest, context: grpc.aio.ServicerContext
    ) -> task_pb2.TaskStatus:
        return self.runner.status()

    async def StreamStatus(
        self, request: task_pb2.GetTaskStatusRequest, context: grpc.aio.ServicerContext
    ) -> AsyncIterator[task_pb2.TaskStatus]:
        with self.runner.status_subscription() as q:
            yield self.runner.status()
            while True:
                yield await q.get()


class TaskService(GrpcShell):
    """The TaskController server, the status ticker and the cycle loop, in one task group."""

    kind = "task"

    def __init__(
        self,
        settings: Settings,
        bus: Bus | None = None,
        grpc_port: int | None = None,
        clients: CellClients | None = None,
        clock: Callable[[], float] | None = None,
    ):
        super().__init__(
            settings.grpc.host,
            settings.grpc.task_port if grpc_port is None else grpc_port,
            cell_token(settings),
        )
        self.settings = settings
        self.clients = clients or CellClients(settings)
        self.bus = bus
        # the controller's clock: given by the composition root, else followed on the bus
        self.controller_clock = ControllerClock() if clock is None and bus is not None else None
        task_clock = clock or self.controller_clock or time.perf_counter
        self.runner = TaskRunner(
            settings,
            self.clients,
            bus,
            spawn=self.spawn,
            clock=task_clock,
            journal=CycleJournal(journal_path(settings)),
        )

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        stack.push_async_callback(self.clients.close)
        if self.controller_clock is not None and self.bus is not None:
            sub = self.bus.subscribe_callback(
                CellKeys(self.settings.cell_id).joint_states, self.controller_clock.on_joint_state
            )
            stack.callback(sub.undeclare)
        self.runner.recover_records()
        await self._serve_grpc(
            stack,
            lambda server: task_pb2_grpc.add_TaskControllerServicer_to_server(
                TaskControllerServicer(self.runner), server
            ),
            "TaskController",
        )
        self.spawn(self._tick(), "status")

    async def _tick(self) -> None:
        period = 1.0 / self.settings.task.status_rate_hz
        while True:
            await asyncio.sleep(period)
            self.runner.publish_status()
            self.runner.republish_pending()


async def serve(settings: Settings, between_cycles: Callable[[Bus], object] | None = None) -> None:
    """``pickplace serve task``; ``between_cycles(bus)`` (from the composition root) runs after each cycle."""
    async with Bus(settings.zenoh) as bus, TaskService(settings, bus) as svc:
        if between_cycles is not None:
            svc.runner.between_cycles = lambda: between_cycles(bus)
        await svc.wait()
