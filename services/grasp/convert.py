"""proto ↔ grasp cores: poses, obstacle boxes, grasps and waypoint plans."""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable

import numpy as np
from pickplace.v1 import common_pb2, grasp_pb2, motion_pb2

from services.common.errors import InvalidInputError
from services.common.messages import matrix_to_pose
from services.common.modes import GripperCommand, MotionKind
from services.grasp.plan import Grasp, HeldObject, PickPlan, Waypoint
from services.kinematics.collision import Box

log = logging.getLogger("pickplace.grasp.convert")

Array = np.ndarray

MOTION = {
    MotionKind.JOINT: grasp_pb2.PickWaypoint.JOINT,
    MotionKind.LINEAR: grasp_pb2.PickWaypoint.LINEAR,
    MotionKind.HOLD: grasp_pb2.PickWaypoint.HOLD,
}
GRIPPER = {
    None: grasp_pb2.PickWaypoint.GRIPPER_NONE,
    GripperCommand.OPEN: grasp_pb2.PickWaypoint.OPEN,
    GripperCommand.CLOSE: grasp_pb2.PickWaypoint.CLOSE,
}


def boxes_from_proto(msgs: Iterable[motion_pb2.CollisionBox]) -> list[Box]:
    return [
        Box.from_bounds(b.x_min, b.x_max, b.y_min, b.y_max, b.z_min, b.z_max, name=b.name or f"box{k}")
        for k, b in enumerate(msgs)
    ]


def grasp_to_proto(g: Grasp) -> grasp_pb2.GraspCandidate:
    return grasp_pb2.GraspCandidate(
        pose=matrix_to_pose(g.T_base_tool),
        quality=g.quality,
        width_quality=g.width_quality,
        epsilon=g.epsilon,
        force_closure=g.force_closure,
        approach_distance=g.approach_distance_m,
        approach_direction=[float(v) for v in g.approach_direction],
        gripper_width=g.width_m,
        opening=g.opening_m,
        force=g.force_n,
        joints=[] if g.q is None else [float(v) for v in g.q],
        label=g.label,
    )


def held_to_proto(h: HeldObject) -> motion_pb2.AttachedObject:
    if h.shape == "cylinder":
        return motion_pb2.AttachedObject(
            shape=motion_pb2.AttachedObject.CYLINDER,
            radius=h.radius,
            length=h.length,
            tool_to_object=matrix_to_pose(h.T_tool_object),
        )
    return motion_pb2.AttachedObject(
        shape=motion_pb2.AttachedObject.BOX, size=list(h.size), tool_to_object=matrix_to_pose(h.T_tool_object)
    )


def waypoint_to_proto(w: Waypoint) -> grasp_pb2.PickWaypoint:
    msg = grasp_pb2.PickWaypoint(
        name=w.name,
        motion=MOTION[w.motion],
        pose=matrix_to_pose(w.T_base_tool),
        joints=[float(v) for v in w.q],
        gripper=GRIPPER[w.gripper],
        holding=w.holding,
    )
    if w.guard is not None:
        msg.guard.CopyFrom(
            grasp_pb2.Guard(
                force_drop_n=w.guard.force_drop_n,
                overtravel_m=w.guard.overtravel_m,
                speed_m_s=w.guard.speed_m_s,
                direction=list(w.guard.direction),
                slow_band_m=w.guard.slow_band_m,
                approach_speed_m_s=w.guard.approach_speed_m_s,
            )
        )
    return msg


def plan_to_proto(plan: PickPlan, planning_time_s: float, stamp_ns: int) -> grasp_pb2.PickPlan:
    metrics = {k: float(v) for k, v in plan.notes.items() if isinstance(v, (int, float))}
    text = {k: v for k, v in plan.notes.items() if isinstance(v, str)}
    summary = f"{plan.task}: {' → '.join(plan.names())}"
    if text:
        summary += " (" + ", ".join(f"{k} {v}" for k, v in text.items()) + ")"
    return grasp_pb2.PickPlan(
        header=common_pb2.Header(stamp_ns=stamp_ns, frame_id="base"),
        task=plan.task,
        waypoints=[waypoint_to_proto(w) for w in plan.waypoints],
        grasp=grasp_to_proto(plan.grasp),
        held_object=held_to_proto(plan.held),
        place_position=[float(v) for v in plan.place_position],
        metrics=metrics,
        summary=summary,
        planning_time_s=planning_time_s,
    )


def joints_or(values: Iterable[float], default: Array, dof: int, name: str) -> Array:
    """Joints from a request (rad), or ``default`` when the field is empty."""
    arr = np.asarray(list(values), dtype=float)
    if arr.size == 0:
        return default.copy()
    if arr.size != dof:
        raise InvalidInputError(f"{name} needs {dof} values, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{name} contains NaN or infinite values: {arr.tolist()}")
    return arr


def rod_size(
    request: grasp_pb2.PickAndStandRequest, configured_length_m: float, configured_diameter_m: float
) -> tuple[float, float]:
    """The rod's (length, diameter) in m as vision measured them; the configured size only for a field
    the request does not carry (said in a log line). A size that is not a positive number is refused."""
    size = []
    for name, configured in (("length", configured_length_m), ("diameter", configured_diameter_m)):
        if not request.HasField(name):
            log.info("the request carries no rod %s: planning with the configured %.4f m", name, configured)
            size.append(configured)
            continue
        value = float(getattr(request, name))
        if not (math.isfinite(value) and value > 0):
            raise InvalidInputError(
                f"rod {name} {value!r} m: a measured size must be a positive number of metres"
            )
        size.append(value)
    return size[0], size[1]
