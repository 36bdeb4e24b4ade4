"""The robot-driver service over real gRPC and Zenoh on loopback."""

import asyncio
import itertools
import statistics

import grpc
import numpy as np
import pytest
from pickplace.v1 import common_pb2, robot_pb2, robot_pb2_grpc

from services.common.bus import Bus
from services.common.errors import InvalidInputError, LimitViolationError, RobotCommunicationError
from services.common.grpc_util import channel, check_health, rpc_errors
from services.common.keys import CellKeys
from services.robot.service import RobotService, robot_link_up
from tests.conftest import free_port

pytestmark = pytest.mark.integration


@pytest.fixture
async def service(robot_settings):  # type: ignore[no-untyped-def]
    async with Bus(robot_settings.zenoh) as bus, RobotService(robot_settings, bus, grpc_port=0) as svc:
        yield svc


@pytest.fixture
async def stub(service):  # type: ignore[no-untyped-def]
    ch = channel("127.0.0.1", service.grpc_port)
    async with ch:
        yield robot_pb2_grpc.RobotControllerStub(ch)


async def test_stream_joint_states_rate(stub):
    # Every feedback packet (125 Hz from the simulator) is forwarded: judged by the driver's sequence
    # numbers and the states' own stamps, not by the wall clock, which a loaded machine stretches.
    stream = stub.StreamJointStates(robot_pb2.StreamJointStatesRequest())
    first = await stream.read()
    msgs = [first]
    while msgs[-1].header.stamp_ns - first.header.stamp_ns < 1_000_000_000:
        msgs.append(await stream.read())
    stream.cancel()
    seqs = [m.header.seq for m in msgs]
    assert all(b > a for a, b in itertools.pairwise(seqs)), "out of order"
    assert len(msgs) >= 0.9 * (seqs[-1] - seqs[0] + 1), f"{len(msgs)} of {seqs[-1] - seqs[0] + 1} forwarded"
    assert len(msgs) >= 30, f"only {len(msgs)} joint states in 1 s of feedback"
    assert len(first.position) == 6
    assert list(first.name) == ["joint1", "joint2", "joint3", "joint4", "joint5", "joint6"]


async def test_stream_rate_limit(stub):
    stream = stub.StreamJointStates(robot_pb2.StreamJointStatesRequest(max_rate_hz=10))
    stamps = [(await stream.read()).header.stamp_ns for _ in range(8)]
    stream.cancel()
    gaps_ms = [(b - a) / 1e6 for a, b in itertools.pairwise(stamps)]
    assert min(gaps_ms) >= 100.0, gaps_ms  # never faster than asked
    assert statistics.median(gaps_ms) < 150.0, gaps_ms  # the first state due, not a slower rate


async def test_second_zenoh_session_receives_joint_states(service, robot_settings):
    zs = robot_settings.zenoh.model_copy(
        update={"listen": [f"tcp/127.0.0.1:{free_port()}"], "connect": robot_settings.zenoh.listen}
    )
    async with Bus(zs) as bus:
        sub = bus.subscribe(CellKeys(robot_settings.cell_id).joint_states, common_pb2.JointState)
        try:
            msgs = [await sub.get(timeout_s=5.0) for _ in range(20)]
        finally:
            sub.close()
    assert all(len(m.position) == 6 for m in msgs)
    assert msgs[-1].header.seq > msgs[0].header.seq
    assert np.allclose(np.rad2deg(msgs[-1].position), [0, 0, 90, 0, -90, 0], atol=1e-6)


async def test_control_rpcs(stub, service):
    await stub.Enable(robot_pb2.EnableRequest())
    target = np.deg2rad([15, 10, 80, 0, -90, 0])
    r = await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=target.tolist(), speed_ratio=100))
    assert r.success and np.allclose(r.final_positions, target, atol=1e-6)
    js = await stub.GetJointStates(robot_pb2.GetJointStatesRequest())
    assert np.allclose(js.position, target, atol=1e-6)
    st = await stub.GetStatus(robot_pb2.GetStatusRequest())
    assert st.robot_mode_name == "ENABLE" and st.enabled and st.robot_model == "nova5"
    g = await stub.SetGripper(robot_pb2.SetGripperRequest(close=True))
    assert g.closed and service.driver.gripper.state().closed
    with pytest.raises(InvalidInputError, match="release applies to an open"), rpc_errors():
        await stub.SetGripper(robot_pb2.SetGripperRequest(close=True, release=True))
    assert service.driver.gripper.state().closed  # refused before anything was sent
    g = await stub.SetGripper(robot_pb2.SetGripperRequest(close=False, release=True))
    assert not g.closed and not g.unchanged and not service.driver.gripper.state().closed
    # open jaws opened again: nothing sent, and the answer says so (the eval charges it no time)
    g = await stub.SetGripper(robot_pb2.SetGripperRequest(close=False))
    assert not g.closed and g.unchanged and g.message == "already open"


async def test_errors_cross_grpc_with_their_type(stub):
    await stub.Enable(robot_pb2.EnableRequest())
    with pytest.raises(grpc.aio.AioRpcError) as err:
        await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=[0, 0, 3.0, 0, 0, 0]))
    assert err.value.code() == grpc.StatusCode.FAILED_PRECONDITION
    assert "LimitViolationError" in err.value.details() and "joint 3" in err.value.details()
    with pytest.raises(LimitViolationError), rpc_errors():
        await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=[0, 0, 3.0, 0, 0, 0]))
    with pytest.raises(InvalidInputError, match="6 values"), rpc_errors():
        await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=[0, 0]))
    with pytest.raises(InvalidInputError, match="NaN"), rpc_errors():
        await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=[0, 0, float("nan"), 0, 0, 0]))


async def test_estop_over_grpc_during_move(stub, service):
    await stub.Enable(robot_pb2.EnableRequest())
    move = asyncio.ensure_future(
        stub.MoveJoints(
            robot_pb2.MoveJointsRequest(
                positions=np.deg2rad([150, 0, 90, 0, -90, 0]).tolist(), speed_ratio=10
            )
        )
    )
    await service.driver.client.wait_feedback(lambda fb: fb.q[0] > np.deg2rad(3), 5.0)
    r = await stub.EmergencyStop(robot_pb2.EmergencyStopRequest())
    assert r.success
    with pytest.raises(grpc.aio.AioRpcError) as err:
        await move
    # labelled end to end: the task's wait-for-operator path, never a retried execution failure
    assert err.value.code() == grpc.StatusCode.FAILED_PRECONDITION
    assert dict(err.value.trailing_metadata() or ())["pickplace-error-type"] == "EmergencyStopError"
    assert service.driver.client.estop_lane.requests == 1  # on the e-stop's own connection
    st = await stub.GetStatus(robot_pb2.GetStatusRequest())
    assert st.estop_active and not st.enabled and 116 in st.alarms


async def test_execute_grasp_lld_13_2(stub, service):
    """ExecuteGrasp: open, approach along the tool axis, straight descent, close, lift — checked first."""
    from services.common.messages import matrix_to_pose
    from services.kinematics import analytic

    await stub.Enable(robot_pb2.EnableRequest())
    drv = service.driver
    q_grasp = np.deg2rad([180.0, 30.0, 100.0, -40.0, -90.0, 0.0])
    T_grasp = analytic.fk(drv.spec, q_grasp, drv.limits.T_flange_tool)
    assert T_grasp[2, 3] > 0.05  # a reachable grasp pose above the table
    r = await stub.ExecuteGrasp(
        robot_pb2.ExecuteGraspRequest(
            grasp_pose=matrix_to_pose(T_grasp), approach_distance=0.08, lift_distance=0.05, speed_scale=1.0
        )
    )
    assert r.success and r.closed and drv.gripper.state().closed
    T_end = analytic.fk(drv.spec, drv.joint_positions(), drv.limits.T_flange_tool)
    assert np.allclose(T_end[:3, 3], T_grasp[:3, 3] + [0, 0, 0.05], atol=1e-3)  # lifted straight up
    # a grasp below the table is refused before anything moves
    T_low = T_grasp.copy()
    T_low[2, 3] = -0.05
    q_before = drv.joint_positions()
    with pytest.raises(grpc.aio.AioRpcError) as err:
        await stub.ExecuteGrasp(robot_pb2.ExecuteGraspRequest(grasp_pose=matrix_to_pose(T_low)))
    assert "LimitViolationError" in err.value.details() or "IKFailureError" in err.value.details()
    assert np.allclose(drv.joint_positions(), q_before, atol=1e-6)


async def test_health_follows_the_robot_link(service):
    said = await check_health("127.0.0.1", service.grpc_port, "robot")
    assert "running, robot controller up" in said
    client = service.driver.client
    # a feedback stream silent for five feedback timeouts is a link that is down
    fb = client.feedback
    assert robot_link_up(client, 0.2, fb.received_ns + 900_000_000)
    assert not robot_link_up(client, 0.2, fb.received_ns + 1_100_000_000)
    await client.close()  # the link goes down under the running service
    with pytest.raises(RobotCommunicationError, match="NOT_SERVING: running, robot controller DOWN"):
        await check_health("127.0.0.1", service.grpc_port, "robot")


async def test_move_request_fields_are_honoured_or_refused_never_ignored(stub, sim_server):
    # issue 13, finding 6: max_velocity / max_acceleration were never read; a NaN ratio was INTERNAL
    target = list(np.deg2rad([10, 5, 85, 0, -90, 10]))
    for fields, named in (
        ({"speed_ratio": float("nan")}, "speed_ratio"),
        ({"speed_ratio": 150.0}, "speed_ratio"),
        ({"max_velocity": 1e-4}, "max_velocity"),
        ({"max_velocity": float("inf")}, "max_velocity"),
        ({"max_acceleration": -1.0}, "max_acceleration"),
    ):
        with pytest.raises(grpc.aio.AioRpcError) as info:
            await stub.MoveJoints(robot_pb2.MoveJointsRequest(positions=target, **fields))
        assert info.value.code() == grpc.StatusCode.INVALID_ARGUMENT and named in info.value.details()
    # a velocity cap of a fifth of the fastest joint's limit reaches the controller as its ratio
    spec_fastest = float(np.max(np.deg2rad([120, 120, 120, 180, 180, 180])))
    before = len(sim_server.controller.command_log)
    r = await stub.MoveJoints(
        robot_pb2.MoveJointsRequest(positions=target, max_velocity=0.2 * spec_fastest, max_acceleration=1.0)
    )
    assert r.success
    sent = [text for _, text in list(sim_server.controller.command_log)[before:] if text.startswith("MovJ")]
    assert sent and "v=20" in sent[-1].replace(" ", "") and "a=" in sent[-1], sent
