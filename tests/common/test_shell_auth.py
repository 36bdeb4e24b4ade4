"""A GrpcShell with the cell's token refuses every call without it (the health check stays open for
probes); the cell's clients send it. Over real gRPC on loopback."""

from __future__ import annotations

import grpc
import pytest
from pickplace.v1 import robot_pb2, robot_pb2_grpc
from pydantic import SecretStr

from services.common import grpc_util
from services.common.settings import Settings
from services.robot.service import RobotService
from services.task.clients import CellClients

TOKEN = "a-cell-token-of-32-characters-xx"


@pytest.fixture
def token_settings(robot_settings: Settings) -> Settings:
    gw = robot_settings.gateway.model_copy(update={"api_token": SecretStr(TOKEN)})
    return robot_settings.model_copy(update={"gateway": gw})


@pytest.mark.integration
async def test_a_call_without_the_cells_token_is_refused_and_one_with_it_served(token_settings):
    async with RobotService(token_settings, grpc_port=0) as svc:
        port = svc.grpc_port
        for token, code in (
            (None, grpc.StatusCode.UNAUTHENTICATED),
            ("not-the-token", grpc.StatusCode.UNAUTHENTICATED),
        ):
            async with grpc_util.channel("127.0.0.1", port, token) as ch:
                stub = robot_pb2_grpc.RobotControllerStub(ch)
                with pytest.raises(grpc.aio.AioRpcError) as err:
                    await stub.EmergencyStop(robot_pb2.EmergencyStopRequest())
                assert err.value.code() == code
                with pytest.raises(grpc.aio.AioRpcError) as streamed:
                    async for _ in stub.StreamJointStates(robot_pb2.StreamJointStatesRequest()):
                        pass
                assert streamed.value.code() == code
        # nothing reached the arm
        assert svc.driver.client.estop_lane.requests == 0
        # the health check stays open (the launcher's and Kubernetes' probes send no token)
        assert "serving" in await grpc_util.check_health("127.0.0.1", port, "robot")
        # the cell's clients carry the token from the same settings
        s = token_settings.model_copy(
            update={"grpc": token_settings.grpc.model_copy(update={"robot_port": port})}
        )
        clients = CellClients(s)
        try:
            assert (await clients.robot.joints()).shape == (6,)
        finally:
            await clients.close()


def test_an_empty_token_is_refused():
    with pytest.raises(ValueError, match="empty token"):
        grpc_util.TokenAuthInterceptor("")


async def test_without_a_token_the_shell_serves_anyone_on_its_port(robot_settings):
    """The default sim profile (tests, a hand-run service): open, with a warning in its log."""
    assert robot_settings.gateway.api_token is None
    async with (
        RobotService(robot_settings, grpc_port=0) as svc,
        grpc_util.channel("127.0.0.1", svc.grpc_port) as ch,
    ):
        js = await robot_pb2_grpc.RobotControllerStub(ch).GetJointStates(robot_pb2.GetJointStatesRequest())
        assert len(js.position) == 6
