"""The authenticated gRPC edge: RobotController relayed to the driver, CellMetrics.StreamMetrics."""

from __future__ import annotations

import grpc
import numpy as np
import pytest
from pickplace.v1 import gateway_pb2, gateway_pb2_grpc, robot_pb2, robot_pb2_grpc

from services.common.bus import Bus
from services.common.errors import LimitViolationError
from services.common.grpc_util import channel, rpc_errors
from services.common.keys import CellKeys
from services.robot.service import RobotService
from tests.gateway.conftest import (
    TOKEN,
    gateway_settings,
    migrate_up,
    pick_event,
    running_gateway,
    wait_until,
)

pytestmark = pytest.mark.integration

META = (("authorization", f"Bearer {TOKEN}"),)


async def test_edge_needs_the_token_and_relays_to_the_driver(robot_settings, sim_server, sqlite_db, tmp_path):
    await migrate_up(sqlite_db)
    s = gateway_settings(robot_settings, sqlite_db, tmp_path, edge_grpc_port=0)
    async with Bus(s.zenoh) as bus, RobotService(s, bus, grpc_port=0) as robot:
        s = s.model_copy(update={"grpc": s.grpc.model_copy(update={"robot_port": robot.grpc_port})})
        async with running_gateway(s, bus) as gw:
            port = gw.cell.edge_port
            assert port
            async with channel("127.0.0.1", port) as ch:
                stub = robot_pb2_grpc.RobotControllerStub(ch)
                metrics = gateway_pb2_grpc.CellMetricsStub(ch)

                # no token, wrong token: nothing reaches the driver
                for md in ((), (("authorization", "Bearer not-the-token-123456"),)):
                    with pytest.raises(grpc.aio.AioRpcError) as err:
                        await stub.Enable(robot_pb2.EnableRequest(), metadata=md)
                    assert err.value.code() == grpc.StatusCode.UNAUTHENTICATED
                    with pytest.raises(grpc.aio.AioRpcError) as err:
                        async for _ in stub.StreamJointStates(
                            robot_pb2.StreamJointStatesRequest(), metadata=md
                        ):
                            break
                    assert err.value.code() == grpc.StatusCode.UNAUTHENTICATED
                    with pytest.raises(grpc.aio.AioRpcError) as err:
                        await stub.EmergencyStop(robot_pb2.EmergencyStopRequest(), metadata=md)
                    assert err.value.code() == grpc.StatusCode.UNAUTHENTICATED
                assert not robot.driver.client.feedback.enabled and not sim_server.controller.estop

                # with the token
                js = await stub.GetJointStates(robot_pb2.GetJointStatesRequest(), metadata=META)
                assert np.allclose(np.rad2deg(js.position), [0, 0, 90, 0, -90, 0], atol=1e-6)
                await stub.Enable(robot_pb2.EnableRequest(), metadata=META)
                target = np.deg2rad([10, 5, 85, 0, -90, 0])
                r = await stub.MoveJoints(
                    robot_pb2.MoveJointsRequest(positions=target.tolist(), speed_ratio=100),
                    metadata=META,
                    timeout=20,
                )
                assert r.success and np.allclose(r.final_positions, target, atol=1e-6)
                with (
                    pytest.raises(LimitViolationError, match="joint 3"),
                    rpc_errors(),
                ):  # the driver's error type
                    await stub.MoveJoints(
                        robot_pb2.MoveJointsRequest(positions=[0, 0, 3.0, 0, 0, 0]), metadata=META
                    )
                n = 0
                async for msg in stub.StreamJointStates(
                    robot_pb2.StreamJointStatesRequest(max_rate_hz=50), metadata=META
                ):
                    assert len(msg.position) == 6
                    n += 1
                    if n == 5:
                        break

                bus.publish(CellKeys(s.cell_id).pick_events, pick_event(0))
                await wait_until(lambda: gw.cell.writer.written == 1, 5.0, "the pick in the database")
                async for sample in metrics.StreamMetrics(
                    gateway_pb2.StreamMetricsRequest(period_s=0.1), metadata=META
                ):
                    assert sample.picks_total == 1 and sample.success_rate == 1.0
                    assert sample.cycle_time == pytest.approx(8.0) and sample.database_ok
                    assert sample.state in ("IDLE", "RUNNING", "ENABLE")
                    break

                r = await stub.EmergencyStop(robot_pb2.EmergencyStopRequest(), metadata=META)
                assert r.success and sim_server.controller.estop
            prom = (await gw.client.get("/metrics")).text
            assert 'emergency_stop_total{cell_id="cell1",robot_id="robot_01",source="grpc"} 1.0' in prom
