"""The GraspPlanner gRPC service over a real loopback channel."""

from __future__ import annotations

from collections.abc import AsyncIterator

import numpy as np
import pytest
from pickplace.v1 import common_pb2, grasp_pb2, grasp_pb2_grpc, motion_pb2

from services.common.errors import ConfigurationError, IKFailureError, InvalidInputError
from services.common.grpc_util import channel, rpc_errors
from services.common.messages import matrix_to_pose, pose_to_matrix
from services.common.modes import TaskKind
from services.common.settings import Settings, load_settings
from services.grasp.geometry import pose, rotation_z
from services.grasp.service import GraspPlannerServicer, GraspService

pytestmark = pytest.mark.integration


def grasp_settings() -> Settings:
    return load_settings("sim", overrides={"logging": {"file": None}, "grpc": {"grasp_port": 0}})


@pytest.fixture
async def stub() -> AsyncIterator[grasp_pb2_grpc.GraspPlannerStub]:
    async with GraspService(grasp_settings(), grpc_port=0) as svc, channel("127.0.0.1", svc.grpc_port) as ch:
        yield grasp_pb2_grpc.GraspPlannerStub(ch)


async def test_compute_grasps_for_a_lying_cylinder(stub) -> None:  # type: ignore[no-untyped-def]
    R = rotation_z(0.5) @ np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    req = grasp_pb2.ComputeGraspsRequest(
        object_pose=matrix_to_pose(pose(R, [0.45, 0.0, 0.011])),
        object_shape="cylinder",
        object_width=0.022,
        object_height=0.2,
        num_candidates=5,
    )
    with rpc_errors():
        res = await stub.ComputeGrasps(req)
    assert res.success and 0 < len(res.grasps) <= 5
    assert res.candidates_generated > len(res.grasps) and sum(res.rejected.values()) > 0
    q = [g.quality for g in res.grasps]
    assert q == sorted(q, reverse=True)
    best = res.grasps[0]
    assert best.force_closure and best.epsilon > 0 and len(best.joints) == 6
    assert list(best.approach_direction) == pytest.approx([0.0, 0.0, -1.0], abs=1e-9)


async def test_plan_pick_and_stand_returns_the_waypoint_plan(stub) -> None:  # type: ignore[no-untyped-def]
    req = grasp_pb2.PickAndStandRequest(center=[0.5, -0.1, 0.011], axis=[0.3, 0.95, 0.0])
    with rpc_errors():
        plan = await stub.PlanPickAndStand(req)
    assert plan.task == TaskKind.STAND_ROD
    names = [w.name for w in plan.waypoints]
    assert names[:4] == ["SAFE_HOME", "PRE_GRASP", "GRASP", "LIFT"]
    assert names.index("REORIENT") < names.index("PLACE_ABOVE") < names.index("PLACE")
    by_name = {w.name: w for w in plan.waypoints}
    # the service checks collisions: the carry goes as joint moves, which the summary says
    carry = names[names.index("LIFT") + 1 : names.index("PLACE")]
    assert all(by_name[n].motion == grasp_pb2.PickWaypoint.JOINT for n in carry), carry
    assert "carry_to_place_above joint moves in 1 part(s)" in plan.summary
    assert by_name["GRASP"].gripper == grasp_pb2.PickWaypoint.CLOSE
    assert by_name["RELEASE"].motion == grasp_pb2.PickWaypoint.HOLD
    assert by_name["PLACE"].HasField("guard") and by_name["PLACE"].guard.force_drop_n == pytest.approx(0.6)
    assert not by_name["LIFT"].HasField("guard")
    assert all(len(w.joints) == 6 for w in plan.waypoints)
    assert plan.held_object.shape == motion_pb2.AttachedObject.CYLINDER
    assert plan.held_object.length == pytest.approx(0.2)
    assert list(plan.place_position) == pytest.approx([0.45, 0.0, 0.0])
    assert plan.metrics["lift_m"] >= 0.15 and plan.planning_time_s > 0
    T = pose_to_matrix(by_name["GRASP"].pose, "grasp")
    assert abs(T[:3, 1] @ np.array([0.3, 0.95, 0.0]) / np.hypot(0.3, 0.95)) < 1e-6


async def test_unreachable_rod_comes_back_as_ik_failure(stub) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(IKFailureError, match="reach"), rpc_errors():
        await stub.PlanPickAndStand(grasp_pb2.PickAndStandRequest(center=[1.5, 0.0, 0.011], axis=[0, 1, 0]))


async def test_nan_input_comes_back_as_invalid_input(stub) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InvalidInputError, match="NaN"), rpc_errors():
        await stub.PlanPickAndStand(
            grasp_pb2.PickAndStandRequest(center=[float("nan"), 0.0, 0.011], axis=[0, 1, 0])
        )
    bad_pose = common_pb2.Pose(x=0.5, qw=0.0)
    with pytest.raises(InvalidInputError, match="quaternion"), rpc_errors():
        await stub.ComputeGrasps(
            grasp_pb2.ComputeGraspsRequest(
                object_pose=bad_pose,
                object_shape="box",
                object_width=0.05,
                object_depth=0.05,
                object_height=0.05,
            )
        )


async def test_plan_pick_and_place_uses_the_colour_zone(stub) -> None:  # type: ignore[no-untyped-def]
    req = grasp_pb2.PickAndPlaceRequest(
        cube_pose=matrix_to_pose(pose(rotation_z(0.2), [0.5, 0.1, 0.025])),
        color="green",
        obstacles=[
            motion_pb2.CollisionBox(
                name="wall", x_min=0.3, x_max=0.5, y_min=0.315, y_max=0.365, z_min=0.0, z_max=0.12
            )
        ],
    )
    with rpc_errors():
        plan = await stub.PlanPickAndPlace(req)
    assert plan.task == TaskKind.SORT_CUBES
    assert list(plan.place_position)[:2] == pytest.approx([0.30, -0.45])
    assert plan.held_object.shape == motion_pb2.AttachedObject.BOX
    with pytest.raises(InvalidInputError, match="purple"), rpc_errors():
        await stub.PlanPickAndPlace(grasp_pb2.PickAndPlaceRequest(cube_pose=req.cube_pose, color="purple"))


def test_a_robot_model_without_a_safe_home_is_a_configuration_error() -> None:
    s = grasp_settings()
    s = s.model_copy(update={"grasp": s.grasp.model_copy(update={"safe_home_joints_deg": {}})})
    with pytest.raises(ConfigurationError, match="safe_home"):
        GraspPlannerServicer(s)


async def test_recovery_hooks_alternative_plan_and_grasp_offset(stub) -> None:  # type: ignore[no-untyped-def]
    base = grasp_pb2.PickAndStandRequest(center=[0.5, -0.05, 0.011], axis=[1.0, 0.0, 0.0])
    with rpc_errors():
        best = await stub.PlanPickAndStand(base)
        alt = await stub.PlanPickAndStand(
            grasp_pb2.PickAndStandRequest(center=base.center, axis=base.axis, alternative=1)
        )
        shifted = await stub.PlanPickAndStand(
            grasp_pb2.PickAndStandRequest(center=base.center, axis=base.axis, grasp_offset=0.03)
        )
    joints = {w.name: list(w.joints) for w in best.waypoints}
    alt_joints = {w.name: list(w.joints) for w in alt.waypoints}
    assert alt_joints["REORIENT"] != pytest.approx(joints["REORIENT"], abs=1e-3)  # another wrist option
    assert alt.metrics["joint_motion_rad"] >= best.metrics["joint_motion_rad"]
    g0 = pose_to_matrix(best.waypoints[2].pose, "grasp")
    g1 = pose_to_matrix(shifted.waypoints[2].pose, "grasp")
    assert abs(abs(g1[0, 3] - g0[0, 3]) - 0.03) < 1e-9 and abs(g1[1, 3] - g0[1, 3]) < 1e-9
    with pytest.raises(InvalidInputError, match="grasp_offset"), rpc_errors():
        await stub.PlanPickAndStand(
            grasp_pb2.PickAndStandRequest(center=base.center, axis=base.axis, grasp_offset=0.5)
        )
