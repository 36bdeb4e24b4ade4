"""From a grasp plan's waypoints to the motion planner's moves, and the boxes of what the cycle places
(pure): where the arm may blend, what is an obstacle on the way, where a blended run ends."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from services.common.frames import make_transform, matrix_to_quat_xyzw, rotation_angle_rad, tool_rotation
from services.common.modes import GripperCommand, MotionKind, TaskKind
from services.kinematics.tool import PLACED_TOP_CLEARANCE_M
from services.kinematics.trajectory import JointTrajectory
from services.task.plan import state_for
from services.task.planned import PlannedPick
from services.task.ports import GraspPlan, Move, Observation, PlannedWaypoint, SeenBox, SeenRod
from services.task.states import CycleState


def move_to(plan: GraspPlan, i: int, further_m: float = 0.0) -> Move | None:
    """The move to waypoint ``i`` of a grasp plan, in its scene; None for a waypoint without motion.
    ``further_m``: a guarded approach taken that much past its overtravel."""
    w = plan.waypoints[i]
    held = plan.held_object if w.holding else None
    if w.motion is MotionKind.HOLD:
        return None
    # what was placed stands there now: an obstacle to the way home and to every move after the release
    # but a line straight out of it (that one starts with the object between the open jaws)
    released = not w.holding and any(p.holding for p in plan.waypoints[:i])
    out_of_jaws = w.motion is MotionKind.LINEAR and i > 0 and plan.waypoints[i - 1].holding
    placed = (placed_box(plan),) if w.name == WAY_HOME or (released and not out_of_jaws) else ()
    if w.motion is MotionKind.JOINT:
        return Move(MotionKind.JOINT, w.joints, held, label=w.name, obstacles=placed)
    guarded = w.guard_force_n > 0
    T = w.T_base_tool.copy()
    if guarded:  # a guarded approach may go as far as the overtravel; touch-down stops it earlier
        T[:3, 3] += (w.guard_overtravel_m + further_m) * w.guard_direction
    lifting_off = w.holding and i > 0 and not plan.waypoints[i - 1].holding
    return Move(
        MotionKind.LINEAR,
        T,
        held,
        slow=guarded,
        table_contact=lifting_off or guarded,
        label=w.name,
        obstacles=placed,
    )


def blends(plan: GraspPlan, i: int) -> bool:
    """Whether the arm may pass waypoint ``i`` without stopping: only physics asks for a stop (the
    jaws closing, a guarded touch-down and the rest before it, a release) — an open of the jaws
    while nothing is held is done before setting off."""
    w = plan.waypoints[i]
    if i + 1 >= len(plan.waypoints):
        return False
    nxt = plan.waypoints[i + 1]
    if w.motion is MotionKind.HOLD or nxt.motion is MotionKind.HOLD:
        return False
    if w.guard_force_n > 0 or nxt.guard_force_n > 0:  # the guard measures its baseline at rest
        return False
    return w.gripper is None or (w.gripper is GripperCommand.OPEN and not w.holding)


def rounds(plan: GraspPlan, i: int) -> bool:
    """Whether the corner at waypoint ``i`` may be rounded: where the arm flows through it, except
    at the end of the move out of a release when the next move is not checked against the placed object
    (the curve leaves the line out of the jaws, whose own scene has not got it: :func:`move_to`)."""
    n = len(plan.waypoints)
    if not blends(plan, i):
        return False
    out_of_release = 0 < i < n and plan.waypoints[i - 1].holding and not plan.waypoints[i].holding
    if not out_of_release:
        return True
    nxt = move_to(plan, i + 1) if i + 1 < n else None
    return nxt is not None and bool(nxt.obstacles)


# a motion from rest that flows on but lasts less than this goes out in one call with the next: the driver
# holds about this much ahead when a call that flows on returns (12 targets at 30 ms), and a shorter one
# left too little in hand by the time the next request came (on the twin at 2-3x its stream fell behind
# and was resumed from rest: the 0.1-0.2 s pre-grasp move after the set-off, 7 times in 30 trials at 3x)
SHORT_FROM_REST_S = 0.36
JOINED_AT = "joined_at"  # a joined trajectory's meta: the joint positions where its parts meet


def sent_along(planned: PlannedPick, i: int) -> JointTrajectory | None:
    """Waypoint ``i + 1``'s motion when it goes out in one call with waypoint ``i``'s, else None: that one
    starts at rest, flows into it and is short (``SHORT_FROM_REST_S``), nothing is done at ``i`` between
    them (no gripper action but an open done before setting off, nothing held, no guard), and ``i + 1``'s
    motion is planned (not still planning in the background) and unguarded."""
    trajs = planned.trajs
    if i + 1 >= min(len(trajs), planned.rest_from):
        return None
    a, b = trajs[i], trajs[i + 1]
    if a is None or b is None or a.starts_in_motion or not a.ends_in_motion:
        return None
    w, nxt = planned.plan.waypoints[i], planned.plan.waypoints[i + 1]
    if a.duration >= SHORT_FROM_REST_S or w.holding or w.guard_force_n > 0 or nxt.guard_force_n > 0:
        return None
    return b if w.gripper is None or w.gripper is GripperCommand.OPEN else None


def joined(a: JointTrajectory, b: JointTrajectory) -> JointTrajectory:
    """``a`` then ``b`` as one trajectory, where they meet kept in its meta (``JOINED_AT``)."""
    out = a.append(b)
    out.meta[JOINED_AT] = [*joined_at(a), a.positions[-1].copy()]
    return out


def joined_at(traj: JointTrajectory) -> list[np.ndarray]:
    """The joint positions where the parts of a joined trajectory meet (none for a plain one)."""
    at = traj.meta.get(JOINED_AT)
    return [np.asarray(q, dtype=float) for q in at] if isinstance(at, list) else []


def run_end(planned: PlannedPick, i: int) -> int:
    """The last waypoint of the blended run that waypoint ``i`` is in (where the arm comes to rest)."""
    end = i
    while end + 1 < len(planned.trajs) and (t := planned.trajs[end]) is not None and t.ends_in_motion:
        end += 1
    return end


WAY_HOME = "HOME"
SAFE_HOME = "SAFE_HOME"


def safe_home_of(plan: GraspPlan) -> np.ndarray | None:
    """The safe home a grasp plan starts at (its SAFE_HOME waypoint), if it has one."""
    first = plan.waypoints[0] if plan.waypoints else None
    return first.joints.copy() if first is not None and first.name == SAFE_HOME else None


# where the set-off ends counts as on the grasp's approach line (the pre-grasp's turn, off the line, along
# it from the pre-grasp, and the joints from the pre-grasp's: the same arm branch)
ON_LINE_RAD = np.deg2rad(0.1)
ON_LINE_M = 0.0005
ON_LINE_ALONG_M = 0.02
ON_LINE_JOINTS_RAD = np.deg2rad(3.0)


def pre_grasp_at(plan: GraspPlan, q: np.ndarray, T_q: np.ndarray) -> GraspPlan:
    """The plan with its pre-grasp where the arm is (joints ``q``, tool pose ``T_q``: where the set-off
    ends) when that lies on the grasp's approach line, turned as the pre-grasp and within
    ``ON_LINE_ALONG_M`` of it: the approach then starts there. Unchanged otherwise. Seen: the set-off
    ends 2-7 mm below or above the pre-grasp (the grasp's height is the fingertips' over the table, not
    the rod's axis), and the move along the line between, 0.1-0.2 s, turned joints back on their way."""
    if (
        len(plan.waypoints) < 2
        or plan.waypoints[0].motion is not MotionKind.JOINT
        or not grasp_approach(plan, 1)
    ):
        return plan
    pre, grasp = plan.waypoints[0], plan.waypoints[1]
    p_pre, p_grasp = pre.T_base_tool[:3, 3], grasp.T_base_tool[:3, 3]
    length = float(np.linalg.norm(p_grasp - p_pre))
    if length <= 2 * ON_LINE_ALONG_M:
        return plan
    d = (p_grasp - p_pre) / length
    off = np.asarray(T_q[:3, 3], dtype=float) - p_pre
    along = float(off @ d)
    if (
        abs(along) > ON_LINE_ALONG_M
        or float(np.linalg.norm(off - along * d)) > ON_LINE_M
        or rotation_angle_rad(pre.T_base_tool[:3, :3], T_q[:3, :3]) > ON_LINE_RAD
        or float(np.max(np.abs(np.asarray(q) - pre.joints))) > ON_LINE_JOINTS_RAD
    ):
        return plan
    at_arm = replace(
        pre, T_base_tool=np.asarray(T_q, dtype=float).copy(), joints=np.asarray(q, dtype=float).copy()
    )
    return replace(plan, waypoints=[at_arm, *plan.waypoints[1:]])


def without_safe_home(plan: GraspPlan) -> GraspPlan:
    """The plan without its move to the safe home: the arm goes straight to the pre-grasp."""
    if not plan.waypoints or plan.waypoints[0].name != SAFE_HOME:
        return plan
    return replace(plan, waypoints=plan.waypoints[1:])


def with_way_home(plan: GraspPlan, target: np.ndarray | None) -> GraspPlan:
    """The plan with a last joint move to ``target`` (the safe home, or the first pose on the way
    there that leaves the camera's view clear), planned and blended with the retract like any other
    move; unchanged when ``target`` is None (the arm may stay where the plan ends)."""
    if target is None or not plan.waypoints:
        return plan
    last = plan.waypoints[-1]
    home = PlannedWaypoint(
        WAY_HOME, MotionKind.JOINT, last.T_base_tool.copy(), np.asarray(target, dtype=float).copy()
    )
    return replace(plan, waypoints=[*plan.waypoints, home])


PARK_STEPS = 10  # poses tried on the joint line from the plan's end to the safe home


def park_pose(start: np.ndarray, home: np.ndarray, clear: Callable[[np.ndarray], bool]) -> np.ndarray | None:
    """Where the arm goes after a plan that ends at ``start``: None when ``start`` already leaves
    the camera's view clear, else the first pose on the straight joint line to ``home`` that does
    (the safe home itself at the latest)."""
    start, home = np.asarray(start, dtype=float), np.asarray(home, dtype=float)
    for k in range(PARK_STEPS):
        q = start + (k / PARK_STEPS) * (home - start)
        if clear(q):
            return None if k == 0 else q
    return home


def placed_box(plan: GraspPlan) -> SeenBox:
    """The placed object's footprint, from the table up to its height."""
    held = plan.held_object
    radius = float(getattr(held, "radius", 0.0) or 0.0) or 0.02
    height = float(getattr(held, "length", 0.0) or 0.0) or 0.06
    if plan.task is TaskKind.SORT_CUBES:
        size = list(getattr(held, "size", []) or [0.05, 0.05, 0.05])
        radius, height = max(size[:2]) / 2, size[2]
    p = np.asarray(plan.place_position, dtype=float)
    height += PLACED_TOP_CLEARANCE_M  # the open jaw's tips the collision model leaves out
    return SeenBox(
        np.array([p[0] - radius, p[1] - radius, 0.0]), np.array([p[0] + radius, p[1] + radius, height])
    )


def box_around(center: np.ndarray, half: float) -> SeenBox:
    lo = np.asarray(center, dtype=float) - half
    lo[2] = min(lo[2], 0.0)  # down to the table
    return SeenBox(lo, np.asarray(center, dtype=float) + half)


def rod_box(rod: SeenRod) -> SeenBox:
    """The box around a seen rod (its axis between its ends, grown by its radius), down to the table."""
    r = rod.diameter / 2
    ends = np.stack([rod.center + s * (rod.length / 2) * rod.axis for s in (1.0, -1.0)])
    lo, hi = ends.min(axis=0) - r, ends.max(axis=0) + r
    lo[2] = min(lo[2], 0.0)
    return SeenBox(lo, hi)


def horizontal(v: np.ndarray) -> np.ndarray:
    """``v`` levelled (its z dropped) and of unit length: the way a rod lying on the table runs."""
    h = np.array([float(v[0]), float(v[1]), 0.0])
    n = float(np.linalg.norm(h))
    return h / n if n > 1e-9 else h


def above_pose(
    center: np.ndarray, height: float, R_now: np.ndarray, across: np.ndarray | None = None
) -> np.ndarray:
    """The tool pose ``height`` above ``center``, straight down, its jaws closing level and across
    ``across`` (a rod's axis) or, without one, along the tool's closing axis in ``R_now`` (the tool's
    rotation now); of the two ways round, the one nearer ``R_now``'s."""
    down = np.array([0.0, 0.0, -1.0])
    closing = np.cross(down, across) if across is not None else R_now[:, 1].copy()
    closing[2] = 0.0
    if float(np.linalg.norm(closing)) < 1e-6:  # no level closing axis there: the tool's x, levelled
        closing = R_now[:, 0].copy()
        closing[2] = 0.0
    if float(np.dot(closing, R_now[:, 1])) < 0:
        closing = -closing
    p = np.asarray(center, dtype=float) + [0.0, 0.0, height]
    return make_transform(tool_rotation(down, closing), p)


def grasp_approach(plan: GraspPlan, i: int) -> bool:
    """Whether waypoint ``i`` is a linear approach whose end the jaws close at, nothing held yet."""
    w = plan.waypoints[i]
    return w.motion is MotionKind.LINEAR and w.gripper is GripperCommand.CLOSE and not w.holding


def raise_waypoint(plan: GraspPlan, i: int, dz: float) -> None:
    """Move waypoint ``i``'s target up by ``dz`` (its joints are planned again from the pose)."""
    w = plan.waypoints[i]
    plan.waypoints[i] = replace(w, T_base_tool=raised(w.T_base_tool, dz))


def seen_higher(obs: Observation, dz: float) -> Observation:
    """``obs`` with the objects to pick ``dz`` higher than seen (the grasp plans from where they lie)."""
    if dz <= 0:
        return obs
    up = np.array([0.0, 0.0, dz])
    return replace(
        obs,
        rods=tuple(replace(r, center=r.center + up) for r in obs.rods),
        cubes=tuple(replace(c, centroid=c.centroid + up) for c in obs.cubes),
    )


def is_last_of(plan: GraspPlan, i: int, state: CycleState) -> bool:
    nxt = plan.waypoints[i + 1].name if i + 1 < len(plan.waypoints) else ""
    return state_for(nxt) is not state


def raised(T: np.ndarray, dz: float) -> np.ndarray:
    out = T.copy()
    out[2, 3] += dz
    return out


def pose_list(T: np.ndarray) -> list[float]:
    q = matrix_to_quat_xyzw(T[:3, :3])
    return [float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), *map(float, q)]


def object_id(rod: SeenRod) -> str:
    return f"rod@{rod.center[0]:.3f},{rod.center[1]:.3f}"
