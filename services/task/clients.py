"""The orchestrator's ports over gRPC: vision, grasp, motion and the robot driver."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pickplace.v1 import (
    common_pb2,
    grasp_pb2,
    grasp_pb2_grpc,
    motion_pb2,
    motion_pb2_grpc,
    robot_pb2,
    robot_pb2_grpc,
    vision_pb2,
    vision_pb2_grpc,
)

from services.common.errors import (
    CameraConnectionError,
    EmergencyStopError,
    PlanningError,
    RobotCommunicationError,
    VisionError,
)
from services.common.frames import make_transform
from services.common.grpc_util import cell_token, channel, rpc_errors
from services.common.messages import matrix_to_pose, pose_to_matrix
from services.common.modes import GripperCommand, MotionKind, TaskKind
from services.common.settings import Settings
from services.kinematics import analytic
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_frame
from services.kinematics.trajectory import JointTrajectory
from services.task.passing import PassWatch
from services.task.ports import (
    GraspPlan,
    GripOutcome,
    HeldRodQuery,
    Move,
    MoveOutcome,
    Observation,
    PlannedWaypoint,
    SeenAxis,
    SeenBox,
    SeenCube,
    SeenRod,
)


def _v(v: vision_pb2.Vec3) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def _vec3(v: np.ndarray) -> vision_pb2.Vec3:
    return vision_pb2.Vec3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def boxes_msg(obstacles: tuple[SeenBox, ...]) -> list[motion_pb2.CollisionBox]:
    return [
        motion_pb2.CollisionBox(
            name=f"obstacle{i}",
            x_min=b.min[0],
            x_max=b.max[0],
            y_min=b.min[1],
            y_max=b.max[1],
            z_min=b.min[2],
            z_max=b.max[2],
        )
        for i, b in enumerate(obstacles)
    ]


# A service that died and came back is reached again within about a second: gRPC's own reconnect
# backoff grows to 120 s, and a cycle's first calls after a restart would fail on a channel still
# waiting out its backoff.
RECONNECT = [
    ("grpc.initial_reconnect_backoff_ms", 200),
    ("grpc.min_reconnect_backoff_ms", 200),
    ("grpc.max_reconnect_backoff_ms", 1000),
]


class CellClients:
    """gRPC channels to the other services, opened once and reused."""

    def __init__(self, settings: Settings):
        g = settings.grpc
        self.settings = settings
        self._channels = {
            name: channel(g.client_host(name), port, cell_token(settings), RECONNECT)  # type: ignore[arg-type]
            for name, port in (
                ("vision", g.vision_port),
                ("grasp", g.grasp_port),
                ("motion", g.motion_port),
                ("robot", g.robot_port),
            )
        }
        self.vision = GrpcVision(vision_pb2_grpc.VisionStub(self._channels["vision"]), g.request_timeout_s)
        # planning requests may take as the PLAN state's deadline allows
        plan_timeout = max(g.request_timeout_s, settings.task.plan_deadline_s)
        self.grasp = GrpcGrasp(grasp_pb2_grpc.GraspPlannerStub(self._channels["grasp"]), plan_timeout)
        self.motion = GrpcMotion(motion_pb2_grpc.MotionPlannerStub(self._channels["motion"]), settings)
        self.robot = GrpcRobot(robot_pb2_grpc.RobotControllerStub(self._channels["robot"]), settings)

    async def close(self) -> None:
        for ch in self._channels.values():
            await ch.close()


class GrpcVision:
    def __init__(self, stub: vision_pb2_grpc.VisionStub, timeout_s: float):
        self._stub, self._timeout = stub, timeout_s

    async def observe(self) -> Observation:
        try:
            with rpc_errors():
                resp = await self._stub.Detect(vision_pb2.DetectRequest(), timeout=self._timeout)
        except RobotCommunicationError as exc:  # for the task, vision unreachable = no camera (retry)
            raise CameraConnectionError(f"vision service unreachable: {exc}") from exc
        objs = resp.objects
        if not objs.calibrated:
            raise VisionError("vision has no camera-to-base calibration; run `pickplace calibrate`")
        rods = tuple(
            SeenRod(_v(r.center_base), _v(r.axis_base), r.length_m, r.diameter_m, r.confidence)
            for r in objs.rods
            if r.has_base
        )
        cubes = tuple(SeenCube(_v(c.centroid_base), c.color_label) for c in objs.cubes if c.has_base)
        boxes = tuple(SeenBox(_v(o.base.min), _v(o.base.max)) for o in objs.obstacles if o.has_base)
        return Observation(rods, cubes, boxes, tuple(objs.notes), float(objs.timings_ms.get("total", 0.0)))

    async def held_rod_axis(self, query: HeldRodQuery) -> SeenAxis:
        req = vision_pb2.MeasureHeldRodRequest(
            point_base=_vec3(query.point),
            direction_base=_vec3(query.direction),
            search_radius_m=query.search_radius_m,
            along_min_m=query.along_min_m,
            along_max_m=query.along_max_m,
            skip_min_m=query.skip_min_m,
            skip_max_m=query.skip_max_m,
            rod_diameter_m=query.rod_diameter_m,
        )
        with rpc_errors():
            resp = await self._stub.MeasureHeldRod(req, timeout=self._timeout)
        return SeenAxis(_v(resp.direction_base), _v(resp.point_base), resp.n_points)


MOTION_KIND = {
    grasp_pb2.PickWaypoint.JOINT: MotionKind.JOINT,
    grasp_pb2.PickWaypoint.MOTION_UNSPECIFIED: MotionKind.JOINT,
    grasp_pb2.PickWaypoint.LINEAR: MotionKind.LINEAR,
    grasp_pb2.PickWaypoint.HOLD: MotionKind.HOLD,
}
GRIPPER_COMMAND = {
    grasp_pb2.PickWaypoint.OPEN: GripperCommand.OPEN,
    grasp_pb2.PickWaypoint.CLOSE: GripperCommand.CLOSE,
}
MOTION_TYPE = {
    MotionKind.JOINT: motion_pb2.MotionWaypoint.JOINT,
    MotionKind.LINEAR: motion_pb2.MotionWaypoint.LINEAR,
}


def _waypoints(plan: grasp_pb2.PickPlan) -> list[PlannedWaypoint]:
    out = []
    for w in plan.waypoints:
        guarded = w.HasField("guard") and w.guard.force_drop_n > 0
        out.append(
            PlannedWaypoint(
                name=w.name,
                motion=MOTION_KIND[w.motion],
                T_base_tool=pose_to_matrix(w.pose),
                joints=np.array(w.joints),
                gripper=GRIPPER_COMMAND.get(w.gripper),
                guard_force_n=w.guard.force_drop_n if guarded else 0.0,
                guard_overtravel_m=w.guard.overtravel_m if guarded else 0.0,
                guard_speed_m_s=w.guard.speed_m_s if guarded else 0.0,
                guard_slow_band_m=w.guard.slow_band_m if guarded else 0.0,
                guard_approach_speed_m_s=w.guard.approach_speed_m_s if guarded else 0.0,
                guard_direction=np.array(w.guard.direction)
                if guarded and len(w.guard.direction) == 3
                else np.array([0.0, 0.0, -1.0]),
                holding=w.holding,
            )
        )
    return out


class GrpcGrasp:
    def __init__(self, stub: grasp_pb2_grpc.GraspPlannerStub, timeout_s: float):
        self._stub, self._timeout = stub, timeout_s

    def _plan(self, plan: grasp_pb2.PickPlan) -> GraspPlan:
        return GraspPlan(
            TaskKind(plan.task),
            _waypoints(plan),
            plan.grasp.quality,
            plan.held_object if plan.HasField("held_object") else None,
            np.array(plan.place_position),
            plan.summary,
        )

    async def plan_rod(
        self,
        rod: SeenRod,
        q_now: np.ndarray,
        obstacles: tuple[SeenBox, ...],
        alternative: int,
        place_xy: np.ndarray | None = None,
        grasp_offset_m: float | None = None,
        other_branches: bool = False,
    ) -> GraspPlan:
        req = grasp_pb2.PickAndStandRequest(
            center=rod.center.tolist(),
            axis=rod.axis.tolist(),
            length=rod.length,  # as measured; the grasp service refuses a size that is not positive
            diameter=rod.diameter,
            current_joints=q_now.tolist(),
            obstacles=boxes_msg(obstacles),
            alternative=alternative,
            place_xy=[] if place_xy is None else list(map(float, place_xy)),
            other_ik_branches=other_branches,
        )
        if grasp_offset_m is not None:
            req.grasp_offset = grasp_offset_m
        with rpc_errors():
            return self._plan(await self._stub.PlanPickAndStand(req, timeout=self._timeout))

    async def plan_cube(
        self, cube: SeenCube, q_now: np.ndarray, obstacles: tuple[SeenBox, ...], alternative: int
    ) -> GraspPlan:
        req = grasp_pb2.PickAndPlaceRequest(
            cube_pose=matrix_to_pose(make_transform(np.eye(3), cube.centroid)),
            size=0.0,
            color=cube.color,
            current_joints=q_now.tolist(),
            obstacles=boxes_msg(obstacles),
            alternative=alternative,
        )
        with rpc_errors():
            return self._plan(await self._stub.PlanPickAndPlace(req, timeout=self._timeout))


class GrpcMotion:
    def __init__(self, stub: motion_pb2_grpc.MotionPlannerStub, settings: Settings):
        self._stub = stub
        self._timeout = max(settings.grpc.request_timeout_s, settings.task.plan_deadline_s)
        self._spec = get_robot(settings.robot.model)
        self._task = settings.task
        self._T_flange_tool = tool_frame(settings)

    def _scene(
        self, obstacles: tuple[SeenBox, ...], held: object | None, table_contact: bool = False
    ) -> motion_pb2.PlanningScene:
        scene = motion_pb2.PlanningScene(boxes=boxes_msg(obstacles))
        if held is not None:
            scene.attached.CopyFrom(held)  # type: ignore[arg-type]
            if table_contact:  # lifting off or setting down: the held object touches the table
                scene.allowed.append(motion_pb2.AllowedCollision(a="attached", b="table"))
        return scene

    def _options(self, held: object | None, slow: bool = False) -> motion_pb2.MotionOptions | None:
        t = self._task
        if slow:
            return motion_pb2.MotionOptions(
                velocity_scale=t.guarded_speed_scale, acceleration_scale=t.guarded_speed_scale
            )
        if held is not None:  # carrying: gentler, so the object does not creep in the grasp
            return motion_pb2.MotionOptions(
                velocity_scale=t.holding_speed_scale, acceleration_scale=t.holding_speed_scale
            )
        return None

    async def plan_moves(
        self,
        start: np.ndarray,
        moves: Sequence[Move],
        obstacles: tuple[SeenBox, ...],
        start_velocity: np.ndarray | None = None,
    ) -> list[JointTrajectory | None]:
        """One PlanWaypoints request; a move carrying the object (or slowed) has its own scene/options."""
        if not moves:
            return []
        req = motion_pb2.PlanWaypointsRequest(start=start.tolist(), scene=self._scene(obstacles, None))
        if start_velocity is not None:
            req.start_velocity.extend(np.asarray(start_velocity, dtype=float).tolist())
        for m in moves:
            wp = motion_pb2.MotionWaypoint(
                motion=MOTION_TYPE[m.kind],
                label=m.label,
                blend=m.blend,
                blend_tolerance_m=m.blend_tolerance_m,
            )
            if m.kind is MotionKind.JOINT and m.target.ndim == 1:
                wp.joints.extend(m.target.tolist())
            else:
                wp.pose.CopyFrom(matrix_to_pose(m.target))
            if m.held is not None or m.obstacles:
                wp.scene.CopyFrom(self._scene(obstacles + m.obstacles, m.held, m.table_contact))
            opts = self._options(m.held, m.slow)
            if opts is not None:
                wp.options.CopyFrom(opts)
            req.waypoints.append(wp)
        with rpc_errors():
            resp = await self._stub.PlanWaypoints(req, timeout=self._timeout)
        segments = [JointTrajectory.from_proto(s) for s in resp.segments]
        if len(segments) != len(moves):
            raise PlanningError(f"the motion service planned {len(segments)} of {len(moves)} moves")
        return [s if len(s) > 1 else None for s in segments]  # one point: already there

    async def tool_pose(self, q: np.ndarray) -> np.ndarray:
        return analytic.fk(self._spec, q, self._T_flange_tool)


class GrpcRobot:
    def __init__(self, stub: robot_pb2_grpc.RobotControllerStub, settings: Settings):
        self._stub = stub
        self._timeout = settings.robot.motion_timeout_s + settings.grpc.request_timeout_s
        self._object_di = settings.gripper.object_di

    async def joints(self) -> np.ndarray:
        with rpc_errors():
            js = await self._stub.GetJointStates(robot_pb2.GetJointStatesRequest(), timeout=self._timeout)
        return np.array(js.position)

    async def execute(
        self, traj: JointTrajectory, force_guard_n: float = 0.0, continues: bool = False
    ) -> MoveOutcome:
        req = robot_pb2.ExecuteTrajectoryRequest(
            trajectory=traj.to_proto(),
            continues=continues,
        )
        if force_guard_n > 0:
            req.force_guard.CopyFrom(robot_pb2.ForceGuard(force_drop_n=force_guard_n))
        with rpc_errors():
            r = await self._stub.ExecuteTrajectory(req, timeout=self._timeout + traj.duration)
        return MoveOutcome(np.array(r.final_positions), r.execution_time, r.stopped_early)

    async def gripper(self, close: bool, release: bool = False) -> GripOutcome:
        with rpc_errors():
            r = await self._stub.SetGripper(
                robot_pb2.SetGripperRequest(close=close, release=release), timeout=self._timeout
            )
        return GripOutcome(
            r.closed, r.object_detected if self._object_di is not None else None, unchanged=r.unchanged
        )

    async def holding(self) -> bool | None:
        if self._object_di is None:
            return None
        with rpc_errors():
            js = await self._stub.GetJointStates(robot_pb2.GetJointStatesRequest(), timeout=self._timeout)
        return self._holds(js, self._object_di)

    @staticmethod
    def _holds(js: common_pb2.JointState, object_di: int) -> bool:
        return bool((js.digital_inputs >> (object_di - 1)) & 1)  # bit n-1 is DI_n

    async def holding_on_passing(self, q: np.ndarray) -> bool | None:
        if self._object_di is None:
            return None
        watch = PassWatch(np.asarray(q, dtype=float))
        states = self._stub.StreamJointStates(robot_pb2.StreamJointStatesRequest(), timeout=self._timeout)
        try:
            with rpc_errors():
                async for js in states:
                    if watch.passed(np.array(js.position)):
                        return self._holds(js, self._object_di)
        finally:
            states.cancel()
        raise RobotCommunicationError("the robot's joint state stream ended before the arm passed the pose")

    async def recover(self) -> None:
        with rpc_errors():
            st = await self._stub.GetStatus(robot_pb2.GetStatusRequest(), timeout=self._timeout)
            if st.estop_active:
                raise EmergencyStopError("the emergency stop is pressed; release it before starting")
            if st.alarms or st.robot_mode in (9, 11):
                await self._stub.ClearError(robot_pb2.ClearErrorRequest(), timeout=self._timeout)
            if not st.enabled or st.alarms:
                await self._stub.Enable(robot_pb2.EnableRequest(), timeout=self._timeout)

    async def stop(self) -> None:
        with rpc_errors():
            await self._stub.Stop(robot_pb2.StopRequest(), timeout=self._timeout)

    async def emergency_stop(self) -> None:
        with rpc_errors():
            await self._stub.EmergencyStop(robot_pb2.EmergencyStopRequest(), timeout=self._timeout)
