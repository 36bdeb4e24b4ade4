"""The MotionPlanner gRPC service over a real loopback channel."""

from __future__ import annotations

import dataclasses
import itertools
import math

import grpc
import numpy as np
import pytest
from pickplace.v1 import common_pb2, motion_pb2, motion_pb2_grpc

from services.common import grpc_util
from services.common.errors import CollisionError, IKFailureError, InvalidInputError
from services.common.frames import make_transform
from services.common.messages import matrix_to_pose, pose_to_matrix
from services.kinematics.model import Kinematics, load_arm
from services.kinematics.tool import tool_geometry
from services.kinematics.trajectory import JointLimits, JointTrajectory, verify_trajectory
from services.motion.planner import MotionPlanner, PathPlan, Plan
from services.motion.service import MotionService

pytestmark = pytest.mark.integration

DOWN = np.diag([1.0, -1.0, -1.0])
Q_PICK = np.deg2rad([162.5, 22.6, 129.3, -61.9, -90.0, -107.5])
Q_PLACE = Q_PICK + np.deg2rad([70, 0, 0, 0, 0, 0])
WALL = motion_pb2.CollisionBox(
    name="wall", x_min=0.25, x_max=0.60, y_min=0.20, y_max=0.26, z_min=0.0, z_max=0.25
)


@pytest.fixture
async def stub(settings):
    async with (
        MotionService(settings, grpc_port=0) as svc,
        grpc_util.channel("127.0.0.1", svc.grpc_port) as ch,
    ):
        yield motion_pb2_grpc.MotionPlannerStub(ch)


@pytest.fixture
def kin(settings):
    return Kinematics(load_arm(settings.robot.model, tool_geometry(settings)))


async def test_plan_joints_around_a_wall(stub, kin):
    req = motion_pb2.PlanJointsRequest(
        start=Q_PICK.tolist(),
        goal=Q_PLACE.tolist(),
        scene=motion_pb2.PlanningScene(boxes=[WALL]),
        options=motion_pb2.MotionOptions(planning_time_s=5.0),
    )
    resp = await stub.PlanJoints(req)
    assert resp.planner == "RRTConnect"
    traj = JointTrajectory.from_proto(resp.trajectory)
    assert np.allclose(traj.positions[0], Q_PICK) and np.allclose(traj.positions[-1], Q_PLACE)
    assert resp.duration_s == pytest.approx(traj.duration)
    verify_trajectory(traj, JointLimits.from_spec(kin.spec), start=Q_PICK, goal=Q_PLACE)
    # the service's own check agrees, and without the wall it is direct
    check = await stub.CheckTrajectory(
        motion_pb2.CheckTrajectoryRequest(
            trajectory=resp.trajectory, scene=motion_pb2.PlanningScene(boxes=[WALL])
        )
    )
    assert check.ok, check.message
    direct = await stub.PlanJoints(motion_pb2.PlanJointsRequest(start=Q_PICK.tolist(), goal=Q_PLACE.tolist()))
    assert direct.planner == "direct"
    # the direct trajectory does hit the wall
    hit = await stub.CheckTrajectory(
        motion_pb2.CheckTrajectoryRequest(
            trajectory=direct.trajectory, scene=motion_pb2.PlanningScene(boxes=[WALL])
        )
    )
    assert not hit.ok and "wall" in hit.message and hit.collision_time_s > 0


async def test_solve_ik_and_plan_to_pose(stub, kin):
    target = make_transform(DOWN, [0.40, -0.20, 0.10])
    resp = await stub.SolveIK(motion_pb2.SolveIKRequest(target=matrix_to_pose(target), seed=Q_PICK.tolist()))
    assert resp.method == "analytic" and len(resp.solutions) >= 2
    assert np.allclose(kin.fk(np.array(resp.best.positions)), target, atol=2e-5)
    assert resp.best.manipulability > 0
    numeric = await stub.SolveIK(
        motion_pb2.SolveIKRequest(target=matrix_to_pose(target), seed=Q_PICK.tolist(), method="numeric")
    )
    assert numeric.method == "numeric" and numeric.position_error < 1e-6
    plan = await stub.PlanJoints(
        motion_pb2.PlanJointsRequest(start=Q_PICK.tolist(), goal_pose=matrix_to_pose(target))
    )
    end = JointTrajectory.from_proto(plan.trajectory).positions[-1]
    assert np.allclose(kin.fk(end), target, atol=2e-5)


async def test_plan_cartesian_and_waypoints(stub, kin):
    top = kin.fk(Q_PICK)
    low = top.copy()
    low[2, 3] -= 0.05
    cart = await stub.PlanCartesian(
        motion_pb2.PlanCartesianRequest(start=Q_PICK.tolist(), poses=[matrix_to_pose(low)])
    )
    assert cart.planner == "cartesian" and cart.path_points > 2
    assert np.allclose(kin.fk(JointTrajectory.from_proto(cart.trajectory).positions[-1]), low, atol=2e-5)
    wps = [
        motion_pb2.MotionWaypoint(
            motion=motion_pb2.MotionWaypoint.LINEAR, pose=matrix_to_pose(low), label="grasp"
        ),
        motion_pb2.MotionWaypoint(
            motion=motion_pb2.MotionWaypoint.LINEAR, pose=matrix_to_pose(top), label="lift"
        ),
        motion_pb2.MotionWaypoint(
            motion=motion_pb2.MotionWaypoint.JOINT, joints=Q_PLACE.tolist(), label="place"
        ),
    ]
    resp = await stub.PlanWaypoints(
        motion_pb2.PlanWaypointsRequest(
            start=Q_PICK.tolist(),
            waypoints=wps,
            scene=motion_pb2.PlanningScene(boxes=[WALL]),
            options=motion_pb2.MotionOptions(planning_time_s=5.0),
        )
    )
    assert resp.planner.split("+") == ["cartesian", "cartesian", "RRTConnect"]
    traj = JointTrajectory.from_proto(resp.trajectory)
    assert np.allclose(traj.positions[-1], Q_PLACE)


async def test_blended_waypoints_flow_through_without_stopping(stub, kin, monkeypatch):
    """A joint move, a line up and a joint move, blended: one motion, faster than stopping at each
    waypoint, cut into one segment per waypoint that ends in motion where the next one continues.
    The blended run's moves are timed only together (timing each on its own was most of the work)."""
    timed_alone: list[str] = []
    timed = MotionPlanner.timed

    def counting(self: MotionPlanner, found: PathPlan) -> Plan:
        timed_alone.append(found.planner)
        return timed(self, found)

    monkeypatch.setattr(MotionPlanner, "timed", counting)
    top = kin.fk(Q_PICK)
    up = top.copy()
    up[2, 3] += 0.06
    q_mid = Q_PICK + np.deg2rad([30, 0, 0, 0, 0, 0])

    def request(blend: bool) -> motion_pb2.PlanWaypointsRequest:
        return motion_pb2.PlanWaypointsRequest(
            start=q_mid.tolist(),
            waypoints=[
                motion_pb2.MotionWaypoint(
                    motion=motion_pb2.MotionWaypoint.JOINT, joints=Q_PICK.tolist(), blend=blend
                ),
                motion_pb2.MotionWaypoint(
                    motion=motion_pb2.MotionWaypoint.LINEAR, pose=matrix_to_pose(up), blend=blend
                ),
                motion_pb2.MotionWaypoint(motion=motion_pb2.MotionWaypoint.JOINT, joints=Q_PLACE.tolist()),
            ],
        )

    stopping = await stub.PlanWaypoints(request(False))
    assert len(timed_alone) == 3  # each move stops: each timed on its own
    blended = await stub.PlanWaypoints(request(True))
    assert len(timed_alone) == 3  # the blended run: no move timed on its own
    segs = [JointTrajectory.from_proto(s) for s in blended.segments]
    assert len(segs) == 3 and not [n for n in blended.notes if "stop at every waypoint" in n]
    assert blended.duration_s < stopping.duration_s
    for a, b in itertools.pairwise(segs):
        assert np.max(np.abs(a.velocities[-1])) > 1e-3  # in motion at the cut
        assert np.allclose(a.positions[-1], b.positions[0]) and np.allclose(a.velocities[-1], b.velocities[0])
    assert np.max(np.abs(segs[-1].velocities[-1])) == 0.0 and np.allclose(segs[-1].positions[-1], Q_PLACE)
    # the cuts fall on the driver's streaming period, the whole within the limits
    period = 0.03
    for seg in segs[:-1]:
        assert seg.duration / period == pytest.approx(round(seg.duration / period), abs=1e-6)
    whole = JointTrajectory.from_proto(blended.trajectory)
    verify_trajectory(whole, dataclasses.replace(JointLimits.from_spec(kin.spec), max_jerk=None), start=q_mid)
    # the line part still passes within a few mm of the waypoint it blends through
    closest = min(np.linalg.norm(kin.fk(q)[:3, 3] - up[:3, 3]) for q in whole.positions)
    assert closest < 0.01


async def test_a_blend_tolerance_rounds_the_corners_over_the_wire_and_a_bad_one_is_refused(stub, kin):
    """The tolerance reaches the planner (the run is faster, its tool within it of the planned path);
    a negative, NaN or too large one is refused by name, and it has no effect on a waypoint the arm
    stops at."""
    up = kin.fk(Q_PICK)
    up[2, 3] += 0.06
    q_mid = Q_PICK + np.deg2rad([30, 0, 0, 0, 0, 0])

    def request(tolerance: float, blend: bool = True) -> motion_pb2.PlanWaypointsRequest:
        return motion_pb2.PlanWaypointsRequest(
            start=q_mid.tolist(),
            waypoints=[
                motion_pb2.MotionWaypoint(
                    motion=motion_pb2.MotionWaypoint.JOINT,
                    joints=Q_PICK.tolist(),
                    blend=blend,
                    blend_tolerance_m=tolerance,
                    label="above",
                ),
                motion_pb2.MotionWaypoint(motion=motion_pb2.MotionWaypoint.LINEAR, pose=matrix_to_pose(up)),
            ],
        )

    exact = await stub.PlanWaypoints(request(0.0))
    rounded = await stub.PlanWaypoints(request(0.01))
    assert rounded.duration_s < exact.duration_s
    whole = JointTrajectory.from_proto(rounded.trajectory)
    # the corner is cut: the tool never reaches the waypoint it flowed past, and stays within 1 cm of
    # the path through it
    closest = min(np.linalg.norm(kin.fk(q)[:3, 3] - kin.fk(Q_PICK)[:3, 3]) for q in whole.positions)
    assert closest > 1e-3
    joint_line = [q_mid + u * (Q_PICK - q_mid) for u in np.linspace(0.0, 1.0, 1000)]
    tool_line = [
        kin.fk(Q_PICK)[:3, 3] + u * (up[:3, 3] - kin.fk(Q_PICK)[:3, 3]) for u in np.linspace(0, 1, 200)
    ]
    ref = np.array([kin.fk(q)[:3, 3] for q in joint_line] + tool_line)
    got = np.array([kin.fk(q)[:3, 3] for q in whole.positions])
    assert np.max(np.min(np.linalg.norm(got[:, None] - ref[None], axis=2), axis=1)) <= 0.011
    stopping = await stub.PlanWaypoints(request(0.01, blend=False))
    assert np.allclose(JointTrajectory.from_proto(stopping.segments[0]).positions[-1], Q_PICK)
    for bad in (-0.01, math.nan, 0.5):
        err = await _error(stub.PlanWaypoints, request(bad))
        assert err.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "waypoint 0 (above): blend_tolerance_m" in err.details()


async def test_attached_object_and_allowed_pairs_reach_the_planner(stub):
    across = make_transform(np.array([[0, 0, 1.0], [0, 1.0, 0], [-1.0, 0, 0]]), [0, 0, 0])
    scene = motion_pb2.PlanningScene(
        boxes=[WALL],
        attached=motion_pb2.AttachedObject(
            shape=motion_pb2.AttachedObject.CYLINDER,
            radius=0.011,
            length=0.2,
            tool_to_object=matrix_to_pose(across),
        ),
        allowed=[motion_pb2.AllowedCollision(a="attached", b="table")],
    )
    resp = await stub.PlanJoints(
        motion_pb2.PlanJointsRequest(
            start=Q_PICK.tolist(),
            goal=Q_PLACE.tolist(),
            scene=scene,
            options=motion_pb2.MotionOptions(planning_time_s=5.0),
        )
    )
    assert resp.planner == "RRTConnect"


async def _error(call, request):
    with pytest.raises(grpc.aio.AioRpcError) as info:
        await call(request)
    return info.value


async def test_errors_cross_the_wire_with_their_names(stub):
    far = make_transform(DOWN, [1.6, 0.0, 0.3])
    err = await _error(
        stub.SolveIK, motion_pb2.SolveIKRequest(target=matrix_to_pose(far), seed=Q_PICK.tolist())
    )
    assert err.code() == grpc.StatusCode.FAILED_PRECONDITION
    assert "1.6000" in err.details()
    assert isinstance(grpc_util.translate(err), IKFailureError)

    err = await _error(
        stub.PlanJoints, motion_pb2.PlanJointsRequest(start=[math.nan] * 6, goal=Q_PLACE.tolist())
    )
    assert err.code() == grpc.StatusCode.INVALID_ARGUMENT and "NaN" in err.details()
    assert isinstance(grpc_util.translate(err), InvalidInputError)

    err = await _error(
        stub.PlanJoints, motion_pb2.PlanJointsRequest(start=Q_PICK.tolist(), goal=[0, 0, 9.0, 0, 0, 0])
    )
    assert err.code() == grpc.StatusCode.INVALID_ARGUMENT and "joint 3" in err.details()

    err = await _error(
        stub.SolveIK, motion_pb2.SolveIKRequest(target=common_pb2.Pose(x=0.3), seed=Q_PICK.tolist())
    )
    assert err.code() == grpc.StatusCode.INVALID_ARGUMENT and "quaternion" in err.details()

    box = motion_pb2.CollisionBox(x_min=0.3, x_max=0.6, y_min=-0.1, y_max=0.1, z_min=0.0, z_max=0.2)
    err = await _error(
        stub.PlanJoints,
        motion_pb2.PlanJointsRequest(
            start=Q_PICK.tolist(), goal=Q_PLACE.tolist(), scene=motion_pb2.PlanningScene(boxes=[box])
        ),
    )
    assert isinstance(grpc_util.translate(err), CollisionError) and "box0" in err.details()

    err = await _error(
        stub.PlanJoints,
        motion_pb2.PlanJointsRequest(
            start=Q_PICK.tolist(), goal=Q_PLACE.tolist(), options=motion_pb2.MotionOptions(robot_model="kuka")
        ),
    )
    assert err.code() == grpc.StatusCode.INVALID_ARGUMENT and "kuka" in err.details()


def test_pose_conversion_round_trip():
    T = make_transform(DOWN, [0.1, -0.2, 0.3])
    assert np.allclose(pose_to_matrix(matrix_to_pose(T)), T)
    with pytest.raises(InvalidInputError, match="NaN"):
        pose_to_matrix(common_pb2.Pose(x=math.nan, qw=1.0))


async def test_moves_are_planned_below_the_workspace_top(stub, kin, settings):
    """A joint move that straightens the arm on the straight line puts the tool above the workspace's top,
    which the driver refuses: the service plans it below (the top stands in its scenes as a box)."""
    start = np.radians([180.0, 0.0, 90.0, 0.0, -90.0, 0.0])  # the safe home
    goal = np.radians([131.0, -42.0, -144.0, -165.0, -71.0, -57.0])  # the elbow bent the other way
    top = settings.robot.workspace.max[2]
    line = [kin.fk(start + t * (goal - start))[2, 3] for t in np.linspace(0.0, 1.0, 41)]
    assert max(line) > top  # the direct way would be refused
    resp = await stub.PlanJoints(
        motion_pb2.PlanJointsRequest(
            start=start.tolist(), goal=goal.tolist(), options=motion_pb2.MotionOptions(planning_time_s=5.0)
        )
    )
    assert resp.planner != "direct"
    traj = JointTrajectory.from_proto(resp.trajectory)
    assert np.allclose(traj.positions[-1], goal)
    assert max(kin.fk(q)[2, 3] for q in traj.positions) <= top


async def test_a_plan_from_the_moving_arm_takes_over_the_tail_of_its_motion(stub, kin):
    """The arm on its way to above the object, the grasp line known since it set off: the rest of the
    way there and the line down, planned from where the arm will be and as fast as it will move there,
    flow on from the motion under way instead of stopping above the object."""
    q_far = Q_PICK + np.deg2rad([40, -10, 10, 0, 0, 0])
    down = kin.fk(Q_PICK)
    down[2, 3] -= 0.06
    period = 0.03
    setting_off = motion_pb2.PlanWaypointsRequest(
        start=q_far.tolist(),
        waypoints=[motion_pb2.MotionWaypoint(motion=motion_pb2.MotionWaypoint.JOINT, joints=Q_PICK.tolist())],
    )
    first = JointTrajectory.from_proto((await stub.PlanWaypoints(setting_off)).segments[0])
    head = first.window(0.0, round(first.duration / 2 / period) * period)
    q_cut, v_cut = head.positions[-1], head.velocities[-1]

    def request(velocity: list[float]) -> motion_pb2.PlanWaypointsRequest:
        return motion_pb2.PlanWaypointsRequest(
            start=q_cut.tolist(),
            start_velocity=velocity,
            waypoints=[
                motion_pb2.MotionWaypoint(
                    motion=motion_pb2.MotionWaypoint.JOINT,
                    joints=Q_PICK.tolist(),
                    blend=True,
                    blend_tolerance_m=0.01,
                    label="above",
                ),
                motion_pb2.MotionWaypoint(motion=motion_pb2.MotionWaypoint.LINEAR, pose=matrix_to_pose(down)),
            ],
        )

    on = await stub.PlanWaypoints(request(v_cut.tolist()))
    rest, line = (JointTrajectory.from_proto(s) for s in on.segments)
    assert np.array_equal(rest.positions[0], q_cut) and np.allclose(rest.velocities[0], v_cut)
    assert rest.ends_in_motion and not line.ends_in_motion  # through above the object without a stop
    assert np.allclose(kin.fk(line.positions[-1])[:3, 3], down[:3, 3], atol=1e-4)
    # the head then the way on, as the driver streams them: no step beyond the acceleration limit
    limits = JointLimits.from_spec(kin.spec)
    whole = head.append(JointTrajectory.from_proto(on.trajectory))
    ts = np.minimum(np.arange(0, math.ceil(whole.duration / period) + 1) * period, whole.duration)
    stream = whole.sample(ts, derivatives=0)[0]
    assert (
        float(np.max(np.abs(np.diff(stream[:-1], 2, axis=0)) / period**2 / limits.max_acceleration)) < 1.001
    )
    # faster than stopping above the object and going down from rest
    at_rest = await stub.PlanWaypoints(
        motion_pb2.PlanWaypointsRequest(
            start=Q_PICK.tolist(),
            waypoints=[
                motion_pb2.MotionWaypoint(motion=motion_pb2.MotionWaypoint.LINEAR, pose=matrix_to_pose(down))
            ],
        )
    )
    assert head.duration + on.duration_s < first.duration + at_rest.duration_s - 0.05
    # at rest (zeros) it is an ordinary plan from rest
    still = await stub.PlanWaypoints(request([0.0] * 6))
    assert not JointTrajectory.from_proto(still.segments[0]).starts_in_motion
    # a velocity of the wrong shape, not finite, or not along the first move: refused by name
    for bad, code, words in (
        ([1.0, 2.0], grpc.StatusCode.INVALID_ARGUMENT, "start_velocity has 2 values"),
        ([math.nan] * 6, grpc.StatusCode.INVALID_ARGUMENT, "start_velocity contains NaN"),
        ((-v_cut).tolist(), grpc.StatusCode.FAILED_PRECONDITION, "not along it"),
    ):
        err = await _error(stub.PlanWaypoints, request(bad))
        assert err.code() == code and words in err.details(), err.details()
