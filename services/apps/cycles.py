"""Driving a running cell over its gRPC and Zenoh interfaces: enable the arm, run pick cycles through
the task service, park the arm after a cycle that gave up, a fresh twin scene between cycles."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from services.common.settings import Settings

log = logging.getLogger("pickplace.launcher")  # the name its log lines had in the launcher


async def enable_robot(settings: Settings) -> None:
    from pickplace.v1 import robot_pb2, robot_pb2_grpc

    from services.common.grpc_util import cell_token, channel, rpc_errors

    async with channel(
        settings.grpc.client_host("robot"), settings.grpc.robot_port, cell_token(settings)
    ) as ch:
        with rpc_errors():
            await robot_pb2_grpc.RobotControllerStub(ch).Enable(robot_pb2.EnableRequest(), timeout=30.0)


async def park_arm(settings: Settings) -> None:
    """After a cycle that gave up: clear alarms, open the jaws and go to SAFE_HOME (out of the camera's view)."""
    import numpy as np
    from pickplace.v1 import robot_pb2, robot_pb2_grpc

    from services.common.grpc_util import cell_token, channel, rpc_errors

    home = np.deg2rad(settings.grasp.safe_home_joints_deg[settings.robot.model]).tolist()
    async with channel(
        settings.grpc.client_host("robot"), settings.grpc.robot_port, cell_token(settings)
    ) as ch:
        stub = robot_pb2_grpc.RobotControllerStub(ch)
        with rpc_errors():
            await stub.ClearError(robot_pb2.ClearErrorRequest(), timeout=30.0)
            await stub.Enable(robot_pb2.EnableRequest(), timeout=30.0)
            await stub.SetGripper(robot_pb2.SetGripperRequest(close=False), timeout=30.0)
            await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=home), timeout=120.0)


async def run_single_cycle(settings: Settings, task: str = "", timeout_s: float = 300.0) -> Any:
    """One pick cycle through the task service's gRPC; returns its PickEvent."""
    from pickplace.v1 import task_pb2, task_pb2_grpc

    from services.common.grpc_util import cell_token, channel, rpc_errors

    async with channel(
        settings.grpc.client_host("task"), settings.grpc.task_port, cell_token(settings)
    ) as ch:
        with rpc_errors():
            return await task_pb2_grpc.TaskControllerStub(ch).RunSingleCycle(
                task_pb2.SingleCycleRequest(task=task), timeout=timeout_s
            )


async def drive_cycles(
    settings: Settings,
    cycles: int = 0,
    on_pick: Callable[[Any], None] | None = None,
    pause_s: float | None = None,
) -> list[Any]:
    """Enable the arm, then run cycles (0 = until cancelled), with a fresh twin scene after each."""
    from services.common.bus import Bus
    from services.sim.bus_link import request_scene_reset

    await enable_robot(settings)
    picks: list[Any] = []
    pause = settings.task.pause_between_cycles_s if pause_s is None else pause_s
    zs = settings.zenoh.model_copy(update={"mode": "client", "listen": []})
    async with Bus(zs) as bus:
        n = 0
        while cycles == 0 or n < cycles:
            n += 1
            try:
                event = await run_single_cycle(settings, settings.task.task)
            except Exception as exc:  # a crashed service mid-cycle: say so, wait, go on
                log.warning("cycle %d did not complete: %s", n, exc)
                await asyncio.sleep(2.0)
                continue
            picks.append(event)
            if on_pick is not None:
                on_pick(event)
            if not event.success:
                try:
                    await park_arm(settings)
                except Exception as exc:
                    log.warning("could not park the arm after cycle %d: %s", n, exc)
            if settings.task.reset_scene_each_cycle and (cycles == 0 or n < cycles):
                try:
                    await request_scene_reset(bus, settings.cell_id)
                except Exception as exc:
                    log.warning("no fresh scene after cycle %d: %s", n, exc)
            await asyncio.sleep(pause)
    return picks
