"""Cube pick-and-place to colour-keyed drop zones (seed 004), a pure planning function.

``SAFE_HOME`` (joint) → ``PRE_GRASP`` (joint, open) → ``GRASP`` (linear, close) → ``LIFT`` (linear, up
to the transport height, over the seen boxes under the way: :func:`services.grasp.way.carry_height`) →
``TRANSPORT`` (joint, above the drop zone) → ``PLACE_ABOVE`` (linear) → ``PLACE`` (guarded linear
descent) → ``RELEASE`` (hold, open) → ``RETRACT`` (linear, up).

Grasps come from the antipodal synthesis (:mod:`synthesis`) restricted to near top-down
approaches, best quality first. For each grasp the cube may be set down turned by any multiple
of 90° about the vertical (a cube looks the same); every (grasp, turn) pair is tracked with the
batched closed-form IK — one branch along the straight pick lines and one along the place lines
— and the best-quality grasp with the least joint motion wins.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from services.common.errors import CollisionError, IKFailureError, InvalidInputError, PlanningError
from services.common.frames import check_transform, finite_vector, invert_transform
from services.common.modes import CubeRelease, GripperCommand, MotionKind, TaskKind
from services.common.settings import GraspSettings
from services.grasp.geometry import pose, pose_path, rotation_z
from services.grasp.plan import Grasp, Guard, HeldObject, PickPlan, Waypoint
from services.grasp.reach import check_reach, track_paths
from services.grasp.synthesis import CollisionCheck, ObjectSpec, synthesize, track_limits
from services.grasp.way import carry_height
from services.kinematics.analytic import fk
from services.kinematics.collision import Box
from services.kinematics.robot_models import RobotSpec

Array = np.ndarray

MAX_GRASPS = 8  # best grasps compared per cube


@dataclass(frozen=True)
class _Option:
    grasp: Grasp
    poses: dict[str, Array]  # key tool poses
    pick: Array  # tool poses PRE_GRASP → GRASP → LIFT
    place: Array  # tool poses TRANSPORT → PLACE_ABOVE → (guard) → PLACE → RETRACT
    held: HeldObject
    i_place: int  # the PLACE pose's index in ``place``


@dataclass(frozen=True)
class CubeObservation:
    T_base_cube: Array  # centre and faces (x, y along the faces, z up), base frame
    size_m: float
    color: str

    @classmethod
    def create(cls, T_base_cube: ArrayLike, size_m: float, color: str) -> CubeObservation:
        T = check_transform(T_base_cube, "cube pose")
        if not (isinstance(size_m, (int, float)) and math.isfinite(size_m) and 0 < size_m <= 0.5):
            raise InvalidInputError(f"cube size must be within (0, 0.5] m, got {size_m!r}")
        if not isinstance(color, str) or not color:
            raise InvalidInputError(f"cube colour must be a non-empty name, got {color!r}")
        return cls(T, float(size_m), color.lower())


def drop_zone(cfg: GraspSettings, color: str) -> Array:
    zones = cfg.cubes.drop_zones_m
    if color not in zones:
        raise InvalidInputError(f"no drop zone for colour {color!r}; configured zones: {sorted(zones)}")
    return np.asarray(zones[color], dtype=float)


def plan_pick_and_place(
    spec: RobotSpec,
    cube: CubeObservation,
    q_current: ArrayLike,
    cfg: GraspSettings,
    T_flange_tool: Array,
    stroke_m: float,
    *,
    q_home: ArrayLike | None = None,
    collision_check: CollisionCheck | None = None,
    alternative: int = 0,
    seen_boxes: Sequence[Box] = (),
) -> PickPlan:
    """The waypoint plan that sorts ``cube`` into its colour's drop zone; ``alternative`` = k > 0 takes
    the k-th next-best feasible grasp/turn option (recovery: regrasp differently). ``seen_boxes``: what
    else stands on the table; the cube is carried over those under its way
    (:func:`services.grasp.way.carry_height`)."""
    if not (isinstance(alternative, int) and alternative >= 0):
        raise InvalidInputError(f"alternative must be a non-negative integer, got {alternative!r}")
    cc = cfg.cubes
    q_now = finite_vector(q_current, spec.dof, "current joints")
    if not spec.within_limits(q_now, tol=1e-6):
        raise InvalidInputError(
            f"current joints {np.round(q_now, 4).tolist()} rad are outside the {spec.name} limits"
        )
    home = q_now if q_home is None else finite_vector(q_home, spec.dof, "safe-home joints")
    zone = drop_zone(cfg, cube.color)
    table = cfg.table_z_m
    size = cube.size_m
    c = cube.T_base_cube[:3, 3]
    check_reach(spec, c, f"{cube.color} cube")
    check_reach(spec, np.array([zone[0], zone[1], table + size]), f"{cube.color} drop zone")

    obj = ObjectSpec("box", cube.T_base_cube, (size, size, size))
    gs = synthesize(obj, cfg, stroke_m)
    max_tilt = math.cos(math.radians(cc.max_approach_tilt_deg))
    grasps = [g for g in gs.grasps if -g.approach_direction[2] >= max_tilt - 1e-9][:MAX_GRASPS]
    if not grasps:
        raise IKFailureError(
            f"no top-down grasp for the {size * 1000:.0f} mm {cube.color} cube at "
            f"({c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}) m ({gs.summary()})"
        )

    T_tool_flange = invert_transform(T_flange_tool)
    step = cfg.path_step_m
    turn0 = math.atan2(zone[1], zone[0]) - math.atan2(c[1], c[0])  # follow J1's swing
    drops = cc.release is CubeRelease.DROP
    release_clearance = cc.drop_clearance_m if drops else cc.place_clearance_m
    options: list[_Option] = []
    for g in grasps:
        T_grasp = g.T_base_tool
        T_tool_cube = invert_transform(T_grasp) @ cube.T_base_cube
        T_pre = T_grasp.copy()
        T_pre[2, 3] += cfg.approach_distance_m
        T_lift = T_grasp.copy()
        hang = max(T_grasp[2, 3] - (c[2] - size / 2), cfg.gripper.fingertip_beyond_tcp_m)
        carry = carry_height(cc.transport_height_m, cc.carry_clearance_m, c, zone, hang, seen_boxes)
        T_lift[2, 3] = max(carry, T_grasp[2, 3] + cfg.lift_m)
        pick = np.vstack([pose_path(T_pre, T_grasp, step)[:-1], pose_path(T_grasp, T_lift, step)])
        for k in range(4):
            R_place = rotation_z(turn0 + k * math.pi / 2) @ T_grasp[:3, :3]
            bottom_to_centre = np.array([0.0, 0.0, size / 2])
            centre = np.array([zone[0], zone[1], table + release_clearance]) + bottom_to_centre
            # the carried cube keeps its pose in the tool: put its centre over the zone
            p_tool = centre - R_place @ T_tool_cube[:3, 3]
            T_place = pose(R_place, p_tool)
            T_above = T_place.copy()
            T_above[2, 3] += cc.place_approach_m
            T_transport = T_place.copy()
            T_transport[2, 3] = max(T_lift[2, 3], T_above[2, 3])
            T_low = T_place.copy()
            T_low[2, 3] -= cc.guard_overtravel_m + cc.place_clearance_m
            T_up = T_place.copy()
            T_up[2, 3] += cc.retract_up_m
            down = [pose_path(T_transport, T_above, step)[:-1]]
            if drops:  # straight down to where the jaws let go
                down.append(pose_path(T_above, T_place, step)[:-1])
            else:  # the guard may take it down to T_low; the release is at T_place
                down += [pose_path(T_above, T_low, step)[:-1], pose_path(T_low, T_place, step, 1)[:-1]]
            i_place = sum(len(p) for p in down)
            place = np.vstack([*down, pose_path(T_place, T_up, step)])
            poses = {
                "PRE_GRASP": T_pre,
                "GRASP": T_grasp,
                "LIFT": T_lift,
                "TRANSPORT": T_transport,
                "PLACE_ABOVE": T_above,
                "PLACE": T_place,
                "RETRACT": T_up,
            }
            held = HeldObject("box", T_tool_cube, size=(size, size, size))
            options.append(_Option(g, poses, pick, place, held, i_place))

    n_pick = max(len(o.pick) for o in options)
    n_place = max(len(o.place) for o in options)
    pick_paths = np.stack([_pad(o.pick, n_pick) for o in options]) @ T_tool_flange
    place_paths = np.stack([_pad(o.place, n_place) for o in options]) @ T_tool_flange
    limits = track_limits(cfg)
    r_pick = track_paths(spec, pick_paths, home, limits)
    # the place lines start where the pick lines ended (the transport is a joint move between them)
    r_place = track_paths(spec, place_paths, r_pick.q[:, -1], limits)
    reasons: list[str] = []
    ranked = []
    for b, o in enumerate(options):
        if not r_pick.ok[b]:
            reasons.append(f"pick: {r_pick.reason[b]}")
            continue
        if not r_place.ok[b]:
            reasons.append(f"place: {r_place.reason[b]}")
            continue
        cost = float(r_pick.cost[b] + r_place.cost[b])
        ranked.append((-round(o.grasp.quality, 3), cost, b, r_pick.q[b], r_place.q[b]))
    ranked.sort(key=lambda t: (t[0], t[1]))
    explain = getattr(collision_check, "explain", None)
    skipped = 0
    for _, cost, b, q_pick, q_place in ranked:
        o = options[b]
        q_pick, q_place = q_pick[: len(o.pick)], q_place[: len(o.place)]
        if collision_check is not None:
            n_pre = len(pose_path(o.poses["PRE_GRASP"], o.poses["GRASP"], step)) - 1
            hit = _collides(q_pick, q_place, n_pre, o.held, collision_check)
            if hit is not None:
                q_hit, h = hit
                what = explain(q_hit, h) if callable(explain) else "a collision"
                reasons.append(f"collision: {what}")
                continue
        if skipped < alternative:
            skipped += 1
            continue
        return _assemble(spec, cube, zone, o, q_pick, q_place, home, cost, cfg, T_flange_tool)
    if skipped:
        raise PlanningError(
            f"alternative {alternative} requested but only {skipped} feasible option(s) exist"
        )
    msg = (
        f"no feasible pick-and-place for the {cube.color} cube at ({c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}) m "
        f"to its drop zone ({zone[0]:.3f}, {zone[1]:.3f}) m; tried {len(options)} grasp/turn options — "
        + "; ".join(sorted(set(reasons))[:3])
    )
    if any(r.startswith("collision") for r in reasons):
        raise CollisionError(msg)
    raise IKFailureError(msg)


def _pad(path: Array, n: int) -> Array:
    """Repeat the last pose so paths of different lengths batch together (a repeat is a zero step)."""
    if len(path) >= n:
        return path
    return np.concatenate([path, np.repeat(path[-1:], n - len(path), axis=0)])


def _collides(
    q_pick: Array, q_place: Array, i_grasp: int, held: HeldObject, check: CollisionCheck
) -> tuple[Array, HeldObject | None] | None:
    """First colliding configuration (every 2nd sample and the ends): empty-handed up to the grasp,
    carrying the cube after it (the checker allows cube–table contact at the drop)."""
    pick_idx = sorted({*range(0, len(q_pick), 2), i_grasp, len(q_pick) - 1})
    for k in pick_idx:
        h = held if k > i_grasp else None
        if check(q_pick[k], h):
            return q_pick[k], h
    for k in sorted({*range(0, len(q_place), 2), len(q_place) - 1}):
        if check(q_place[k], held):
            return q_place[k], held
    return None


def _assemble(
    spec: RobotSpec,
    cube: CubeObservation,
    zone: Array,
    o: _Option,
    q_pick: Array,
    q_place: Array,
    home: Array,
    cost: float,
    cfg: GraspSettings,
    T_flange_tool: Array,
) -> PickPlan:
    cc = cfg.cubes
    P, grasp, held, i_place = o.poses, o.grasp, o.held, o.i_place
    n_pre = len(pose_path(P["PRE_GRASP"], P["GRASP"], cfg.path_step_m)) - 1
    n_above = len(pose_path(P["TRANSPORT"], P["PLACE_ABOVE"], cfg.path_step_m)) - 1
    # a drop needs no guard: the arm flows down through PLACE_ABOVE and rests only where the jaws open
    guard = (
        None
        if cc.release is CubeRelease.DROP
        else Guard(
            cc.touch_force_drop_n,
            cc.guard_overtravel_m + cc.place_clearance_m,
            cc.guard_speed_m_s,
            slow_band_m=cc.guard_slow_band_m,
            approach_speed_m_s=cc.guard_approach_speed_m_s,
        )
    )
    T_home = fk(spec, home) @ T_flange_tool
    wps = (
        Waypoint("SAFE_HOME", T_home, MotionKind.JOINT, home.copy()),
        Waypoint(
            "PRE_GRASP", P["PRE_GRASP"], MotionKind.JOINT, q_pick[0].copy(), gripper=GripperCommand.OPEN
        ),
        Waypoint("GRASP", P["GRASP"], MotionKind.LINEAR, q_pick[n_pre].copy(), gripper=GripperCommand.CLOSE),
        Waypoint("LIFT", P["LIFT"], MotionKind.LINEAR, q_pick[-1].copy(), holding=True),
        Waypoint("TRANSPORT", P["TRANSPORT"], MotionKind.JOINT, q_place[0].copy(), holding=True),
        Waypoint("PLACE_ABOVE", P["PLACE_ABOVE"], MotionKind.LINEAR, q_place[n_above].copy(), holding=True),
        Waypoint("PLACE", P["PLACE"], MotionKind.LINEAR, q_place[i_place].copy(), guard=guard, holding=True),
        Waypoint(
            "RELEASE",
            P["PLACE"],
            MotionKind.HOLD,
            q_place[i_place].copy(),
            gripper=GripperCommand.OPEN,
            holding=True,
        ),
        Waypoint("RETRACT", P["RETRACT"], MotionKind.LINEAR, q_place[-1].copy()),
    )
    return PickPlan(
        task=TaskKind.SORT_CUBES,
        waypoints=wps,
        grasp=replace(grasp, q=q_pick[n_pre].copy()),
        held=held,
        place_position=np.array([zone[0], zone[1], cfg.table_z_m]),
        notes={
            "drop_zone": cube.color,
            "joint_motion_rad": cost,
            "transport_height_m": float(P["LIFT"][2, 3]),
        },
    )
