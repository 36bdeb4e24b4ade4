"""The grasp service: ``GraspPlanner`` over gRPC, a stateless shell over the grasp cores.

Each request carries the object, the arm's current joints and the obstacle boxes; defaults come
from ``settings.grasp`` (and the rod / cube sizes from ``settings.vision``). Planning runs in a
worker thread with its own collision checker (pinocchio data are per thread), so the event loop
stays responsive. Errors are pickplace errors, translated to gRPC status codes by the common
interceptor.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable
from typing import TypeVar

import grpc
import numpy as np
from pickplace.v1 import grasp_pb2, grasp_pb2_grpc
from prometheus_client import Counter, Histogram
from pydantic import ValidationError

from services.common import grpc_util
from services.common.errors import ConfigurationError, InvalidInputError
from services.common.messages import pose_to_matrix
from services.common.settings import RodStandSettings, Settings
from services.common.shell import GrpcShell, cell_token
from services.grasp.collision import MotionCollisionCheck
from services.grasp.convert import (
    boxes_from_proto,
    grasp_to_proto,
    joints_or,
    plan_to_proto,
    rod_size,
)
from services.grasp.cube import CubeObservation, plan_pick_and_place
from services.grasp.rod import RodObservation, plan_pick_and_stand
from services.grasp.synthesis import ObjectSpec, compute_grasps
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_frame

log = logging.getLogger("pickplace.grasp.service")

REQUESTS = Counter("pickplace_grasp_requests_total", "Grasp service requests", ["rpc", "outcome"])
PLANNING_SECONDS = Histogram(
    "pickplace_grasp_planning_seconds",
    "Wall time of a grasp planning request",
    ["rpc"],
    buckets=(0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0),
)

T = TypeVar("T")


class GraspPlannerServicer(grasp_pb2_grpc.GraspPlannerServicer):
    def __init__(self, settings: Settings):
        self.settings = settings
        self.cfg = settings.grasp
        model = settings.robot.model
        self.spec = get_robot(model)
        self.T_flange_tool = tool_frame(settings)
        home_deg = self.cfg.safe_home_joints_deg.get(model)
        if home_deg is None:
            raise ConfigurationError(
                f"grasp.safe_home_joints_deg has no entry for robot model {model!r} "
                f"(has {sorted(self.cfg.safe_home_joints_deg)})"
            )
        self.home = np.radians(np.asarray(home_deg, dtype=float))
        if not self.spec.within_limits(self.home):
            raise ConfigurationError(
                f"grasp.safe_home_joints_deg[{model!r}] = {home_deg} is outside the joint limits"
            )
        self.stroke_m = settings.gripper.stroke_m

    async def _run(self, rpc: str, fn: Callable[[], T]) -> T:
        return await grpc_util.run_metered(rpc, fn, REQUESTS, PLANNING_SECONDS)

    async def ComputeGrasps(
        self, request: grasp_pb2.ComputeGraspsRequest, context: grpc.aio.ServicerContext
    ) -> grasp_pb2.ComputeGraspsResponse:
        def work() -> grasp_pb2.ComputeGraspsResponse:
            obj = ObjectSpec.from_request(
                request.object_shape,
                pose_to_matrix(request.object_pose, "object_pose"),
                request.object_width,
                request.object_depth,
                request.object_height,
            )
            seed = joints_or(request.current_joints, self.home, self.spec.dof, "current_joints")
            check = MotionCollisionCheck.from_settings(self.settings, boxes_from_proto(request.obstacles))
            result = compute_grasps(
                obj,
                self.spec,
                self.T_flange_tool,
                seed,
                self.cfg,
                self.stroke_m,
                collision_check=check,
                num_candidates=request.num_candidates or None,
                check_reach=not request.skip_reachability,
            )
            return grasp_pb2.ComputeGraspsResponse(
                grasps=[grasp_to_proto(g) for g in result.grasps],
                success=bool(result.grasps),
                message=result.summary(),
                candidates_generated=result.generated,
                rejected=result.rejected,
            )

        return await self._run("ComputeGrasps", work)

    async def PlanPickAndStand(
        self, request: grasp_pb2.PickAndStandRequest, context: grpc.aio.ServicerContext
    ) -> grasp_pb2.PickPlan:
        def work() -> grasp_pb2.PickPlan:
            t0 = time.perf_counter()
            rod_cfg = self.settings.vision.rod
            length, diameter = rod_size(request, rod_cfg.length_m, rod_cfg.diameter_m)
            rod = RodObservation.create(list(request.center), list(request.axis), length, diameter)
            q_now = joints_or(request.current_joints, self.home, self.spec.dof, "current_joints")
            boxes = boxes_from_proto(request.obstacles)
            check = MotionCollisionCheck.from_settings(self.settings, boxes)
            cfg = self.cfg
            if request.HasField("grasp_offset"):
                try:
                    stand_cfg = RodStandSettings.model_validate(
                        {**cfg.rod.model_dump(), "grasp_offset_m": request.grasp_offset}
                    )
                except ValidationError as exc:
                    raise InvalidInputError(
                        f"grasp_offset {request.grasp_offset} m: {exc.errors()[0]['msg']}"
                    ) from exc
                cfg = cfg.model_copy(update={"rod": stand_cfg})
            plan = plan_pick_and_stand(
                self.spec,
                rod,
                q_now,
                cfg,
                self.T_flange_tool,
                self.stroke_m,
                q_home=self.home,
                place_xy=list(request.place_xy) if len(request.place_xy) else None,
                collision_check=check,
                alternative=request.alternative,
                other_branches=request.other_ik_branches,
                seen_boxes=boxes,
            )
            return plan_to_proto(plan, time.perf_counter() - t0, time.time_ns())

        return await self._run("PlanPickAndStand", work)

    async def PlanPickAndPlace(
        self, request: grasp_pb2.PickAndPlaceRequest, context: grpc.aio.ServicerContext
    ) -> grasp_pb2.PickPlan:
        def work() -> grasp_pb2.PickPlan:
            t0 = time.perf_counter()
            cube = CubeObservation.create(
                pose_to_matrix(request.cube_pose, "cube_pose"),
                request.size or self.settings.vision.cubes.cube_size_m,
                request.color,
            )
            q_now = joints_or(request.current_joints, self.home, self.spec.dof, "current_joints")
            boxes = boxes_from_proto(request.obstacles)
            check = MotionCollisionCheck.from_settings(self.settings, boxes)
            plan = plan_pick_and_place(
                self.spec,
                cube,
                q_now,
                self.cfg,
                self.T_flange_tool,
                self.stroke_m,
                q_home=self.home,
                collision_check=check,
                alternative=request.alternative,
                seen_boxes=boxes,
            )
            return plan_to_proto(plan, time.perf_counter() - t0, time.time_ns())

        return await self._run("PlanPickAndPlace", work)


class GraspService(GrpcShell):
    """The GraspPlanner server (stateless: each request carries what it plans for)."""

    kind = "grasp"

    def __init__(self, settings: Settings, grpc_port: int | None = None):
        """``grpc_port``: None = ``settings.grpc.grasp_port``; 0 = any free port."""
        super().__init__(
            settings.grpc.host,
            settings.grpc.grasp_port if grpc_port is None else grpc_port,
            cell_token(settings),
        )
        self.settings = settings
        self.servicer = GraspPlannerServicer(settings)  # a bad safe-home entry fails here, before serving

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        await self._serve_grpc(
            stack,
            lambda server: grasp_pb2_grpc.add_GraspPlannerServicer_to_server(self.servicer, server),
            "GraspPlanner",
        )


async def serve(settings: Settings) -> None:
    """``pickplace serve grasp``: run until cancelled."""
    async with GraspService(settings) as svc:
        await svc.wait()
