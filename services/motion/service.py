"""The motion service: ``MotionPlanner`` over gRPC, a stateless shell over the planning cores.

Every request carries its start state, scene and options; defaults come from
``settings.motion``. Planning runs in a worker thread (one planner, hence one set of
pinocchio data, per request), so the event loop stays responsive. Errors are raised as
pickplace errors and translated to gRPC status codes by the common interceptor.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Callable, Iterable
from typing import TypeVar

import grpc
import numpy as np
from pickplace.v1 import motion_pb2, motion_pb2_grpc
from prometheus_client import Counter, Histogram

from services.common import grpc_util
from services.common.bus import Bus
from services.common.errors import InvalidInputError
from services.common.messages import pose_to_matrix
from services.common.settings import MotionSettings, Settings
from services.common.shell import GrpcShell, cell_token
from services.kinematics.collision import AttachedObject, Box, Scene
from services.kinematics.model import ArmModel, Kinematics, load_arm
from services.kinematics.robot_models import ROBOTS
from services.kinematics.tool import tool_geometry
from services.kinematics.trajectory import Array, JointTrajectory
from services.motion.planner import BlendPart, MotionPlanner, Plan, PlannerConfig, time_runs
from services.motion.timing import moving_start

log = logging.getLogger("pickplace.motion.service")

REQUESTS = Counter("pickplace_motion_requests_total", "Motion service requests", ["rpc", "outcome"])
PLANNING_SECONDS = Histogram(
    "pickplace_motion_planning_seconds",
    "Wall time of a planning request",
    ["rpc"],
    buckets=(0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0),
)

T = TypeVar("T")

# a joint waypoint this close to where the arm already is (every joint) plans no motion
ALREADY_THERE_RAD = 1e-9
MAX_BLEND_TOLERANCE_M = 0.1  # a corner rounded further is a different path, to be planned as one


# --- proto ↔ core ---------------------------------------------------------------------------------


def _joints(values: Iterable[float], name: str) -> Array:
    arr = np.asarray(list(values), dtype=np.float64)
    if arr.size == 0:
        raise InvalidInputError(f"{name} is empty")
    return arr


def _start_velocity(values: Iterable[float], dof: int) -> Array | None:
    """A request's start velocity: None at rest (empty or all zero); one finite value per joint."""
    v = np.asarray(list(values), dtype=np.float64)
    if v.size == 0:
        return None
    if v.size != dof:
        raise InvalidInputError(f"start_velocity has {v.size} values for {dof} start joints")
    if not np.all(np.isfinite(v)):
        raise InvalidInputError("start_velocity contains NaN or infinite values")
    return moving_start(v, dof)


CEILING_HALF_SPAN_M = 10.0  # the box standing for the workspace's top: wider than any arm's reach


def scene_from_proto(
    msg: motion_pb2.PlanningScene, motion: MotionSettings, ceiling_z: float | None = None
) -> Scene:
    """The planning scene of a request; ``ceiling_z``: the workspace's top (robot.workspace), a box above
    it, so a move is planned below it rather than refused by the driver's workspace check (a joint move
    that straightens the arm puts the tool 1.2 m up)."""
    boxes = []
    for k, b in enumerate(msg.boxes):
        boxes.append(
            Box.from_bounds(b.x_min, b.x_max, b.y_min, b.y_max, b.z_min, b.z_max, name=b.name or f"box{k}")
        )
    if ceiling_z is not None:
        span = CEILING_HALF_SPAN_M
        boxes.append(
            Box.from_bounds(-span, span, -span, span, ceiling_z, ceiling_z + 1.0, name="workspace top")
        )
    attached = None
    if msg.HasField("attached"):
        a = msg.attached
        T_tool_object = (
            pose_to_matrix(a.tool_to_object, "attached.tool_to_object")
            if a.HasField("tool_to_object")
            else np.eye(4)
        )
        shape = "box" if a.shape == motion_pb2.AttachedObject.BOX else "cylinder"
        size = tuple(a.size) if shape == "box" else (0.05, 0.05, 0.05)
        if shape == "box" and len(size) != 3:
            raise InvalidInputError(f"attached box needs 3 sizes, got {list(a.size)}")
        attached = AttachedObject(
            shape=shape,
            radius=a.radius or 0.011,
            length=a.length or 0.2,
            size=size,  # type: ignore[arg-type]
            T_tool_object=tuple(map(tuple, T_tool_object)),
        )
    table_z = None if msg.no_table else (msg.table_z if msg.HasField("table_z") else motion.table_z_m)
    return Scene(
        boxes=tuple(boxes),
        table_z=table_z,
        attached=attached,
        padding_m=msg.padding if msg.HasField("padding") else motion.padding_m,
        box_y_extension_m=msg.box_y_extension
        if msg.HasField("box_y_extension")
        else motion.box_y_extension_m,
        allowed=frozenset((p.a, p.b) for p in msg.allowed),
    )


def config_from_options(opts: motion_pb2.MotionOptions, motion: MotionSettings) -> PlannerConfig:
    base = PlannerConfig.from_settings(motion)
    return PlannerConfig(
        planner=opts.planner or base.planner,
        time_budget_s=opts.planning_time_s or base.time_budget_s,
        collision_resolution_rad=base.collision_resolution_rad,
        velocity_scale=opts.velocity_scale or base.velocity_scale,
        acceleration_scale=opts.acceleration_scale or base.acceleration_scale,
        knot_period_s=opts.knot_period_s or base.knot_period_s,
        cartesian_step_m=base.cartesian_step_m,
        cartesian_step_rad=base.cartesian_step_rad,
        jump_threshold_rad=base.jump_threshold_rad,
        min_manipulability=base.min_manipulability,
    )


def plan_response(plan: Plan) -> motion_pb2.PlanResponse:
    meta = plan.trajectory.meta
    return motion_pb2.PlanResponse(
        trajectory=plan.trajectory.to_proto(),
        planner=plan.planner,
        planning_time_s=plan.planning_time_s,
        timing_time_s=plan.timing_time_s,
        duration_s=plan.trajectory.duration,
        path_points=int(plan.path.shape[0]),
        notes=plan.notes,
        velocity_ratio=float(meta.get("velocity_ratio", 0.0)),  # type: ignore[arg-type]
        acceleration_ratio=float(meta.get("acceleration_ratio", 0.0)),  # type: ignore[arg-type]
        jerk_ratio=float(meta.get("jerk_ratio", 0.0)),  # type: ignore[arg-type]
    )


# --- the servicer ---------------------------------------------------------------------------------
class MotionPlannerServicer(motion_pb2_grpc.MotionPlannerServicer):
    def __init__(self, settings: Settings):
        self.settings = settings
        self.motion = settings.motion
        self.tool = tool_geometry(settings)

    async def on_config(self, new: Settings, changed: list[str]) -> None:
        """PUT /config: planner, time budget and speed scales apply from the next request."""
        self.settings = new
        self.motion = new.motion

    def _arm(self, model: str) -> ArmModel:
        name = model or self.settings.robot.model
        if name not in ROBOTS:
            raise InvalidInputError(f"unknown robot model {name!r}; known: {sorted(ROBOTS)}")
        return load_arm(name, self.tool)

    def _planner(self, scene: motion_pb2.PlanningScene, opts: motion_pb2.MotionOptions) -> MotionPlanner:
        return MotionPlanner(
            self._arm(opts.robot_model),
            scene_from_proto(scene, self.motion, ceiling_z=self.settings.robot.workspace.max[2]),
            config_from_options(opts, self.motion),
        )

    async def _run(self, rpc: str, fn: Callable[[], T]) -> T:
        return await grpc_util.run_metered(rpc, fn, REQUESTS, PLANNING_SECONDS)

    async def SolveIK(
        self, request: motion_pb2.SolveIKRequest, context: grpc.aio.ServicerContext
    ) -> motion_pb2.SolveIKResponse:
        def work() -> motion_pb2.SolveIKResponse:
            kin = Kinematics(self._arm(request.robot_model))
            T_ = pose_to_matrix(request.target, "target")
            seed = _joints(request.seed, "seed") if len(request.seed) else np.zeros(kin.dof)
            method = request.method or "auto"
            sol = kin.solve_ik(T_, seed, method=method, min_manipulability=self.motion.min_manipulability)
            others = []
            if sol.method == "analytic":
                others = [
                    motion_pb2.IKSolution(positions=q.tolist(), manipulability=kin.manipulability(q))
                    for q in kin.ik_analytic(T_, seed)
                ]
            return motion_pb2.SolveIKResponse(
                best=motion_pb2.IKSolution(positions=sol.q.tolist(), manipulability=sol.manipulability),
                solutions=others,
                method=sol.method,
                position_error=sol.position_error_m,
                rotation_error=sol.rotation_error_rad,
            )

        return await self._run("SolveIK", work)

    async def PlanJoints(
        self, request: motion_pb2.PlanJointsRequest, context: grpc.aio.ServicerContext
    ) -> motion_pb2.PlanResponse:
        def work() -> motion_pb2.PlanResponse:
            planner = self._planner(request.scene, request.options)
            start = _joints(request.start, "start")
            if len(request.goal):
                plan = planner.plan_joints(
                    start, _joints(request.goal, "goal"), shortest_angle=request.shortest_angle
                )
            elif request.HasField("goal_pose"):
                plan = planner.plan_to_pose(start, pose_to_matrix(request.goal_pose, "goal_pose"))
            else:
                raise InvalidInputError("PlanJoints needs a joint goal or a goal_pose")
            return plan_response(plan)

        return await self._run("PlanJoints", work)

    async def PlanCartesian(
        self, request: motion_pb2.PlanCartesianRequest, context: grpc.aio.ServicerContext
    ) -> motion_pb2.PlanResponse:
        def work() -> motion_pb2.PlanResponse:
            planner = self._planner(request.scene, request.options)
            poses = [pose_to_matrix(p, f"poses[{k}]") for k, p in enumerate(request.poses)]
            return plan_response(planner.plan_cartesian(_joints(request.start, "start"), poses))

        return await self._run("PlanCartesian", work)

    async def PlanWaypoints(
        self, request: motion_pb2.PlanWaypointsRequest, context: grpc.aio.ServicerContext
    ) -> motion_pb2.PlanResponse:
        def work() -> motion_pb2.PlanResponse:
            if not request.waypoints:
                raise InvalidInputError("a waypoint plan needs at least one waypoint")
            start = q = _joints(request.start, "start")
            start_velocity = _start_velocity(request.start_velocity, start.size)
            names: tuple[str, ...] = ()
            parts: list[BlendPart | None] = []  # per waypoint: its checked path (None: already there)
            paths, used = [q[None]], []
            notes: list[str] = []
            planning_s = 0.0
            for k, w in enumerate(request.waypoints):
                # each waypoint exactly as its own PlanJoints / PlanCartesian request would plan it
                planner = self._planner(
                    w.scene if w.HasField("scene") else request.scene,
                    w.options if w.HasField("options") else request.options,
                )
                names = planner.names
                what = f"waypoints[{k}]"
                goal = _joints(w.joints, f"{what}.joints") if len(w.joints) else None
                if goal is None and not w.HasField("pose"):
                    raise InvalidInputError(
                        f"waypoint {k} ({w.label or 'unlabelled'}) has neither pose nor joints"
                    )
                if w.motion == motion_pb2.MotionWaypoint.LINEAR:
                    T_goal = pose_to_matrix(w.pose, f"{what}.pose") if goal is None else planner.kin.fk(goal)
                    found = planner.line_path(q, [T_goal])
                elif goal is None:
                    found = planner.path_to_pose(q, pose_to_matrix(w.pose, f"{what}.pose"))
                elif float(np.max(np.abs(goal - q))) < ALREADY_THERE_RAD:
                    parts.append(None)  # nothing to move
                    continue
                else:
                    found = planner.joints_path(q, goal)
                tol = w.blend_tolerance_m
                if not (math.isfinite(tol) and 0.0 <= tol <= MAX_BLEND_TOLERANCE_M):
                    raise InvalidInputError(
                        f"waypoint {k} ({w.label or 'unlabelled'}): blend_tolerance_m must be within "
                        f"[0, {MAX_BLEND_TOLERANCE_M}] m, got {tol}"
                    )
                line = w.motion == motion_pb2.MotionWaypoint.LINEAR
                parts.append(BlendPart(planner, found, line, tol if w.blend else 0.0))
                paths.append(found.path[1:])
                used.append(found.planner)
                planning_s += found.planning_time_s
                q = found.path[-1]
            t_timing = time.perf_counter()
            blends = [w.blend for w in request.waypoints]
            pieces, timing_notes = time_runs(
                parts, blends, self.settings.robot.servo_period_s, start, names, start_velocity
            )
            notes += timing_notes
            timing_s = time.perf_counter() - t_timing
            whole = JointTrajectory.hold(names, start)
            for piece in pieces:
                whole = whole.append(piece) if len(piece) > 1 else whole
            resp = plan_response(Plan(whole, np.vstack(paths), "+".join(used), planning_s, timing_s, notes))
            resp.segments.extend(piece.to_proto() for piece in pieces)
            return resp

        return await self._run("PlanWaypoints", work)

    async def CheckTrajectory(
        self, request: motion_pb2.CheckTrajectoryRequest, context: grpc.aio.ServicerContext
    ) -> motion_pb2.CheckTrajectoryResponse:
        def work() -> motion_pb2.CheckTrajectoryResponse:
            planner = self._planner(request.scene, request.options)
            traj = JointTrajectory.from_proto(request.trajectory)
            result = planner.check_trajectory(traj, check_collisions=not request.skip_collisions)
            rep = result.limits
            return motion_pb2.CheckTrajectoryResponse(
                ok=result.ok,
                message=result.message,
                velocity_ratio=rep.velocity_ratio if rep else 0.0,
                acceleration_ratio=rep.acceleration_ratio if rep else 0.0,
                jerk_ratio=rep.jerk_ratio if rep else 0.0,
                collision_time_s=result.collision_time_s or 0.0,
            )

        return await self._run("CheckTrajectory", work)


# --- the shell ----------------------------------------------------------------------------------
class MotionService(GrpcShell):
    """The MotionPlanner server; with a bus it follows PUT /config (planner, budgets, scales)."""

    kind = "motion"

    def __init__(self, settings: Settings, bus: Bus | None = None, grpc_port: int | None = None):
        """``grpc_port``: None = ``settings.grpc.motion_port``; 0 = any free port."""
        super().__init__(
            settings.grpc.host,
            settings.grpc.motion_port if grpc_port is None else grpc_port,
            cell_token(settings),
        )
        self.settings = settings
        self.bus = bus
        self.servicer = MotionPlannerServicer(settings)

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        load_arm(self.settings.robot.model, tool_geometry(self.settings))  # fail fast on a bad model/tool
        await self._serve_grpc(
            stack,
            lambda server: motion_pb2_grpc.add_MotionPlannerServicer_to_server(self.servicer, server),
            "MotionPlanner",
        )
        if self.bus is not None:
            self.follow_config(self.bus, self.settings, self.servicer.on_config)


async def serve(settings: Settings) -> None:
    """``pickplace serve motion``: run until cancelled, following PUT /config changes over Zenoh."""
    async with Bus(settings.zenoh) as bus, MotionService(settings, bus) as svc:
        await svc.wait()
