"""The task's gRPC ports against the real motion and grasp servicers on a loopback channel."""

from __future__ import annotations

from collections.abc import AsyncIterator

import grpc
import numpy as np
import pytest
from pickplace.v1 import grasp_pb2_grpc, motion_pb2, motion_pb2_grpc

from services.common import grpc_util
from services.common.errors import InvalidInputError
from services.common.frames import make_transform
from services.common.messages import matrix_to_pose
from services.common.modes import MotionKind, TaskKind
from services.common.settings import Settings
from services.grasp.service import GraspPlannerServicer
from services.kinematics.model import Kinematics, load_arm
from services.kinematics.tool import tool_geometry
from services.kinematics.trajectory import JointTrajectory
from services.motion.service import MotionPlannerServicer
from services.task.clients import GrpcGrasp, GrpcMotion
from services.task.ports import Move, SeenBox, SeenRod

pytestmark = pytest.mark.integration

Q_PICK = np.deg2rad([162.5, 22.6, 129.3, -61.9, -90.0, -107.5])
Q_PLACE = Q_PICK + np.deg2rad([70, 0, 0, 0, 0, 0])
# in the scene but out of the way: every move is direct or a line (sampling-based detours draw from
# the process's one random stream, so two requests for one detour differ)
BOX = SeenBox(np.array([-0.60, -0.60, 0.0]), np.array([-0.50, -0.50, 0.10]))
# a 20 cm rod held across the jaws
HELD = motion_pb2.AttachedObject(
    shape=motion_pb2.AttachedObject.CYLINDER,
    radius=0.011,
    length=0.2,
    tool_to_object=matrix_to_pose(
        make_transform(np.array([[0, 0, 1.0], [0, 1.0, 0], [-1.0, 0, 0]]), [0, 0, 0])
    ),
)


@pytest.fixture
async def channel(settings: Settings) -> AsyncIterator[grpc.aio.Channel]:
    server = grpc_util.create_server()
    motion_pb2_grpc.add_MotionPlannerServicer_to_server(MotionPlannerServicer(settings), server)
    grasp_pb2_grpc.add_GraspPlannerServicer_to_server(GraspPlannerServicer(settings), server)
    port = grpc_util.bind(server, "127.0.0.1", 0)
    await server.start()
    try:
        async with grpc_util.channel("127.0.0.1", port) as ch:
            yield ch
    finally:
        await server.stop(grace=None)


@pytest.fixture
def kin(settings: Settings) -> Kinematics:
    return Kinematics(load_arm(settings.robot.model, tool_geometry(settings)))


def _lowered(T: np.ndarray, dz: float) -> np.ndarray:
    out = T.copy()
    out[2, 3] -= dz
    return out


async def test_one_waypoint_request_plans_each_move_as_its_own_request_would(
    channel: grpc.aio.Channel, settings: Settings, kin: Kinematics
) -> None:
    motion = GrpcMotion(motion_pb2_grpc.MotionPlannerStub(channel), settings)
    top = kin.fk(Q_PICK)
    moves = [
        Move(MotionKind.JOINT, Q_PICK, label="already there"),
        Move(MotionKind.LINEAR, _lowered(top, 0.05), label="down"),
        Move(MotionKind.LINEAR, top, HELD, table_contact=True, label="lift off"),
        Move(MotionKind.JOINT, Q_PLACE, HELD, label="carry"),
        Move(
            MotionKind.LINEAR,
            _lowered(kin.fk(Q_PLACE), 0.04),
            HELD,
            slow=True,
            table_contact=True,
            label="set down",
        ),
    ]
    trajs = await motion.plan_moves(Q_PICK, moves, (BOX,))
    assert len(trajs) == len(moves) and trajs[0] is None
    # each segment is exactly what a PlanJoints / PlanCartesian request for that move alone gives
    stub = motion_pb2_grpc.MotionPlannerStub(channel)
    q = Q_PICK
    for m, traj in zip(moves[1:], trajs[1:], strict=True):
        assert traj is not None
        scene = motion._scene((BOX,), m.held, m.table_contact)
        options = motion._options(m.held, m.slow)
        if m.kind is MotionKind.JOINT:
            alone = await stub.PlanJoints(
                motion_pb2.PlanJointsRequest(
                    start=q.tolist(), goal=m.target.tolist(), scene=scene, options=options
                )
            )
        else:
            alone = await stub.PlanCartesian(
                motion_pb2.PlanCartesianRequest(
                    start=q.tolist(), poses=[matrix_to_pose(m.target)], scene=scene, options=options
                )
            )
        expected = JointTrajectory.from_proto(alone.trajectory)
        assert np.array_equal(traj.positions, expected.positions), m.label
        assert np.array_equal(traj.times, expected.times), m.label
        q = traj.positions[-1]


async def test_a_move_carries_its_own_speed(
    channel: grpc.aio.Channel, settings: Settings, kin: Kinematics
) -> None:
    task = settings.task.model_copy(update={"guarded_speed_scale": 0.1})
    motion = GrpcMotion(
        motion_pb2_grpc.MotionPlannerStub(channel), settings.model_copy(update={"task": task})
    )
    down = _lowered(kin.fk(Q_PICK), 0.05)
    normal, back, slow = await motion.plan_moves(
        Q_PICK,
        [
            Move(MotionKind.LINEAR, down, label="normal"),
            Move(MotionKind.JOINT, Q_PICK, label="back"),
            Move(MotionKind.LINEAR, down, slow=True, label="guarded"),
        ],
        (),
    )
    assert normal is not None and back is not None and slow is not None
    # the same line, guarded: at task.guarded_speed_scale (here 0.1) of the limits (a short line is
    # acceleration-bound: √10 slower)
    assert slow.duration > 2 * normal.duration


async def test_a_joint_move_without_joints_or_a_pose_is_refused_before_any_request() -> None:
    with pytest.raises(InvalidInputError, match="joint positions or a 4×4 tool pose"):
        Move(MotionKind.JOINT, np.eye(3), label="bad")
    with pytest.raises(InvalidInputError, match="a 4×4 tool pose"):
        Move(MotionKind.LINEAR, Q_PICK, label="bad")


async def test_a_joint_move_to_a_pose_goes_to_its_ik_solution_nearest_the_start(
    channel: grpc.aio.Channel, settings: Settings, kin: Kinematics
) -> None:
    """The set-off move: a joint move to a tool pose, exactly as a PlanJoints request to that pose plans it."""
    motion = GrpcMotion(motion_pb2_grpc.MotionPlannerStub(channel), settings)
    target = kin.fk(Q_PLACE)
    (traj,) = await motion.plan_moves(Q_PICK, [Move(MotionKind.JOINT, target, label="set off")], (BOX,))
    assert traj is not None
    assert np.allclose(kin.fk(traj.positions[-1]), target, atol=1e-6)
    alone = await motion_pb2_grpc.MotionPlannerStub(channel).PlanJoints(
        motion_pb2.PlanJointsRequest(
            start=Q_PICK.tolist(), goal_pose=matrix_to_pose(target), scene=motion._scene((BOX,), None)
        )
    )
    assert np.array_equal(traj.positions, JointTrajectory.from_proto(alone.trajectory).positions)


async def test_the_grasp_plan_is_built_around_the_measured_rod(
    channel: grpc.aio.Channel, settings: Settings
) -> None:
    grasp = GrpcGrasp(grasp_pb2_grpc.GraspPlannerStub(channel), 30.0)
    home = np.deg2rad(settings.grasp.safe_home_joints_deg[settings.robot.model])
    rod = SeenRod(np.array([0.5, -0.1, 0.011]), np.array([0.3, 0.95, 0.0]), 0.19, 0.021, 0.9)
    plan = await grasp.plan_rod(rod, home, (), 0)
    assert plan.task is TaskKind.STAND_ROD
    assert plan.held_object.length == pytest.approx(0.19)  # type: ignore[attr-defined]
    assert plan.held_object.radius == pytest.approx(0.0105)  # type: ignore[attr-defined]
    assert settings.vision.rod.length_m != pytest.approx(0.19)  # not the configured rod
    with pytest.raises(InvalidInputError, match=r"rod diameter 0\.0 m"):
        await grasp.plan_rod(SeenRod(rod.center, rod.axis, 0.19, 0.0, 0.9), home, (), 0)
    with pytest.raises(InvalidInputError, match=r"rod length nan m"):
        await grasp.plan_rod(SeenRod(rod.center, rod.axis, float("nan"), 0.021, 0.9), home, (), 0)
