"""The e-stop's path: its own connection to the controller, so it never waits behind a command the
controller is still working on; labelled EmergencyStopError through the driver and gRPC."""

from __future__ import annotations

import asyncio
import contextlib

import grpc
import numpy as np
import pytest
from pickplace.v1 import robot_pb2, robot_pb2_grpc

from services import dobot
from services.common.errors import EmergencyStopError
from services.common.grpc_util import channel, translate
from services.kinematics.interpolation import quintic_move
from services.kinematics.trajectory import JointLimits
from services.robot.client import DobotClient
from services.robot.service import RobotService
from tests.conftest import HOME
from tests.robot.test_link_faults import FAST_RECONNECT, steady

pytestmark = pytest.mark.integration


class SerialDashboard:
    """A controller dashboard that works through each connection's commands in order, one at a time,
    as a real one does: ``GetAngle()`` takes until ``release`` is set."""

    def __init__(self) -> None:
        self.release = asyncio.Event()
        self.seen: list[tuple[int, str]] = []  # (connection number, command)
        self._connections = 0
        self._servers: list[asyncio.base_events.Server] = []
        self._writers: list[asyncio.StreamWriter] = []

    async def __aenter__(self) -> SerialDashboard:
        dash = await asyncio.start_server(self._dashboard, "127.0.0.1", 0)
        feed = await asyncio.start_server(self._feedback, "127.0.0.1", 0)
        self._servers = [dash, feed]
        self.ports = {
            "dashboard": dash.sockets[0].getsockname()[1],
            "feedback": feed.sockets[0].getsockname()[1],
        }
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.release.set()
        for w in self._writers:
            w.transport.abort()
        for srv in self._servers:
            srv.close()

    async def _dashboard(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._connections += 1
        conn = self._connections
        self._writers.append(writer)
        framer = dobot.CommandFramer()
        with contextlib.suppress(ConnectionError, asyncio.CancelledError):
            while data := await reader.read(4096):
                for cmd in framer.feed(data):
                    self.seen.append((conn, cmd))
                    if cmd.startswith("GetAngle"):
                        await self.release.wait()
                    writer.write(f"0,{{}},{cmd};".encode())
                await writer.drain()

    async def _feedback(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writers.append(writer)
        with contextlib.suppress(ConnectionError, asyncio.CancelledError):
            await steady(writer)


async def test_the_estop_overtakes_a_command_the_controller_is_still_working_on():
    async with SerialDashboard() as ctl:
        c = DobotClient(
            "127.0.0.1",
            ctl.ports["dashboard"],
            ctl.ports["feedback"],
            request_timeout_s=30.0,
            reconnect=FAST_RECONNECT,
        )
        async with c:
            slow = asyncio.ensure_future(c.raw_request("GetAngle()"))
            while not any(cmd.startswith("GetAngle") for _, cmd in ctl.seen):
                await c.next_feedback()
            await c.emergency_stop()  # answered while GetAngle() still holds the main connection
            assert not slow.done()
            (main_conn, _), (lane_conn, estop) = ctl.seen
            assert estop == dobot.emergency_stop(True) and lane_conn != main_conn
            assert c.estop_lane.requests == 1
            ctl.release.set()
            await slow


async def test_an_estop_during_a_streamed_trajectory_is_labelled_over_grpc(robot_settings):
    async with RobotService(robot_settings, grpc_port=0) as svc:
        d = svc.driver
        await d.enable()
        lim = JointLimits.from_spec(d.spec, velocity_scale=0.3, acceleration_scale=0.3)
        traj = quintic_move(
            d.joint_positions(),
            HOME + np.deg2rad([60, 0, 0, 0, 0, 0]),
            joint_names=d.spec.joint_names,
            limits=lim,
        )
        async with channel("127.0.0.1", svc.grpc_port) as ch:
            stub = robot_pb2_grpc.RobotControllerStub(ch)
            call = asyncio.ensure_future(
                stub.ExecuteTrajectory(robot_pb2.ExecuteTrajectoryRequest(trajectory=traj.to_proto()))
            )
            await d.client.wait_feedback(lambda f: f.q[0] - HOME[0] > np.deg2rad(3), 10.0)
            await stub.EmergencyStop(robot_pb2.EmergencyStopRequest())
            with pytest.raises(grpc.aio.AioRpcError) as err:
                await call
            assert err.value.code() == grpc.StatusCode.FAILED_PRECONDITION
            assert isinstance(translate(err.value), EmergencyStopError)
            # refused while the e-stop holds, with the same label
            with pytest.raises(grpc.aio.AioRpcError) as again:
                await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=HOME.tolist()))
            assert isinstance(translate(again.value), EmergencyStopError)


def test_the_driver_process_nice_value_is_validated(settings):
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="process_nice"):
        settings.robot.model_validate({**settings.robot.model_dump(), "process_nice": 30})
