"""Joint moves that may replace the rod plan's tool lines (pure). A tool line ties the joints together;
the joints alone get there sooner (seed 1003: the lines took 1.83 s from the grasp to above the place,
the joints need 1.51 s). The rod planner (:mod:`services.grasp.rod`) tracks the tool lines first; this
decides, per waypoint of the carry, whether its joint move may replace its line (:func:`joint_carry`),
and whether the rise after the retract may go on the straight joint line home instead of straight up
above the standing rod (:func:`home_from_retract`, :func:`rise_toward_home`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from services.common.settings import GraspSettings
from services.grasp.geometry import cylinder_lowest_z, lowest_gripper_z
from services.grasp.plan import HeldObject
from services.grasp.reach import origin_heights, singularity_margin
from services.grasp.synthesis import CollisionCheck, track_limits
from services.kinematics.analytic import fk
from services.kinematics.collision import Box
from services.kinematics.interpolation import densify
from services.kinematics.robot_models import RobotSpec
from services.kinematics.tool import PLACED_TOP_CLEARANCE_M

Array = np.ndarray

CARRY_KEYS = ("LIFT", "REORIENT", "CARRY", "PLACE_ABOVE")  # the carry's waypoints, from the lift on
STEP_RAD = math.radians(1.0)  # the largest joint step between the checked samples of a joint move
UPRIGHT_COS = math.cos(math.radians(10.0))  # a rod this near upright is let down, not swung, near the table
MAX_TURN_PARTS = 3  # the turn as joint moves in up to this many parts (through the tool line's joints)
COLLISION_STRIDE = 2  # collisions checked at every 2nd dense sample (and the key poses / the last)
# the standing rod's box is this much wider and taller than the one the task's way home is planned past
# (services.task.moves.placed_box: the rod's radius, its length + PLACED_TOP_CLEARANCE_M): more than the
# motion planner's search clearance, so the way home it plans is the straight joint line checked here
STANDING_MARGIN_M = 0.01


def joint_line(qa: Array, qb: Array) -> Array:
    """The straight joint line from ``qa`` (left out) to ``qb``, sampled at most ``STEP_RAD`` apart."""
    return densify(np.stack([qa, qb]), STEP_RAD)[1:]


@dataclass(frozen=True)
class CarryMove:
    """How the held rod goes to one waypoint of the carry: by joint moves through ``via`` (indices of the
    tracked path: the tool line's own joints on the way) when ``why_line`` is empty, else along its tool
    line. ``passed``: the waypoint is left out, the joint move to the next goes on from the one before."""

    why_line: str
    via: tuple[int, ...] = ()
    passed: bool = False

    def describe(self) -> str:
        if self.why_line:
            return f"tool line: {self.why_line}"
        return (
            "passed by (the joint move goes on)"
            if self.passed
            else f"joint moves in {len(self.via) + 1} part(s)"
        )


@dataclass(frozen=True)
class CarryFloors:
    """Where the held rod's lowest point must stay (base z): above ``turn_m`` while it turns, above
    ``upright_m`` once upright (it is let down so toward the place)."""

    turn_m: float
    upright_m: float


def joint_carry(
    spec: RobotSpec,
    q_path: Array,
    key_index: dict[str, int],
    held: HeldObject,
    floors: CarryFloors,
    cfg: GraspSettings,
    T_flange_tool: Array,
    check: CollisionCheck | None,
) -> dict[str, CarryMove]:
    """How the held rod goes to each waypoint of the carry after the lift (REORIENT, CARRY, PLACE_ABOVE),
    the tool lines tracked as ``q_path`` (``key_index``: where each waypoint is on it).

    The turn goes as one joint move from the lift, else through the tool line's joints at the half or at
    the thirds of the way (``MAX_TURN_PARTS``), else along its line. The upright rod then goes straight
    to above the place when it may (CARRY passed), else to CARRY and on, each as a joint move or a line.

    A joint move passes when, sampled at most ``STEP_RAD`` apart, the rod lengthened by the grasp
    tolerance stays above ``floors``, the fingers above the table, the elbow and wrist off the table and
    away from singularities, and nothing collides with the rod held. Joints in limits at both ends are in
    limits between them. Without a collision check the carry keeps to the tool lines (laid over what
    stands on the way)."""
    if check is None:
        return {b: CarryMove("no collision check") for b in CARRY_KEYS[1:]}
    g, table = cfg.gripper, cfg.table_z_m
    limits = track_limits(cfg)
    opening = held.radius * 2 + g.width_margin_m
    length = held.length + 2 * cfg.rod.offset_tolerance_m

    def why_not(qa: Array, qb: Array, floor: float) -> str:
        """Why the joint move from ``qa`` to ``qb`` fails a check ("" when it passes); ``floor``: the
        rod's lowest point while it is tilted."""
        q = joint_line(qa, qb)
        n = len(q)
        T_tool = fk(spec, q, T_flange_tool)
        T_rod = T_tool @ held.T_tool_object
        lows = cylinder_lowest_z(T_rod[:, :3, 3], T_rod[:, :3, 2], held.radius, length)
        short = lows - np.where(np.abs(T_rod[:, 2, 2]) >= UPRIGHT_COS, floors.upright_m, floor)
        if float(short.min()) < 0.0:
            low = float(lows[int(np.argmin(short))])
            return f"the rod end would come within {max(low - table, 0.0) * 1000:.0f} mm of the table"
        if float(lowest_gripper_z(g, T_tool, opening).min()) < table + g.table_clearance_m - 1e-9:
            return "the fingers would touch the table"
        if float(origin_heights(spec, q)[:, 2:].min()) < limits.table_z_m + limits.arm_table_clearance_m:
            return f"the elbow or wrist would come within {limits.arm_table_clearance_m:.2f} m of the table"
        if float(singularity_margin(spec, q).min()) < limits.min_singularity_sin:
            return "it passes near a wrist or elbow singularity"
        if any(check(q[k], held) for k in [*range(0, n - 1, COLLISION_STRIDE), n - 1]):
            return "a collision with the rod held"
        return ""

    lift, turn, carry, above = (key_index[k] for k in CARRY_KEYS)
    out: dict[str, CarryMove] = {"REORIENT": CarryMove("")}
    for parts in range(1, MAX_TURN_PARTS + 1):  # the turn, through the tool line's joints on the way
        knots = [lift + round(k * (turn - lift) / parts) for k in range(parts + 1)]
        why = next((w for u, v in pairwise(knots) if (w := why_not(q_path[u], q_path[v], floors.turn_m))), "")
        out["REORIENT"] = CarryMove(why, () if why else tuple(knots[1:-1]))
        if not why:
            break
    # the upright rod from the turn to above the place: straight there in joint space where it may
    up = floors.upright_m
    if not why_not(q_path[turn], q_path[above], up):
        return {**out, "CARRY": CarryMove("", passed=True), "PLACE_ABOVE": CarryMove("")}
    out["CARRY"] = CarryMove(why_not(q_path[turn], q_path[carry], up))
    out["PLACE_ABOVE"] = CarryMove(why_not(q_path[carry], q_path[above], up))
    return out


def standing_rod_box(
    place_xy: Array, table_z: float, radius: float, length: float, offset_tolerance_m: float
) -> Box:
    """The rod stood at ``place_xy``: from the table to its top held ``offset_tolerance_m`` high, taller
    by what the collision model leaves out at the open jaw's tips, ``STANDING_MARGIN_M`` all round."""
    r = radius + STANDING_MARGIN_M
    top = table_z + length + offset_tolerance_m + PLACED_TOP_CLEARANCE_M + STANDING_MARGIN_M
    return Box(
        (place_xy[0] - r, place_xy[1] - r, table_z), (place_xy[0] + r, place_xy[1] + r, top), "standing rod"
    )


def home_from_retract(q_retract: Array, q_home: Array, standing: Box, check: CollisionCheck | None) -> str:
    """Why the arm may not go home in one joint move from the retract, past the rod it stood ("" when it
    may): the straight joint line from ``q_retract`` to the safe home ``q_home`` (the task parks on it,
    short of home where the camera's view is clear) sampled by :func:`joint_line`, checked with the rod's
    box ``standing`` added to the scene. Otherwise the arm first rises above the rod (RETRACT_UP), as
    the plan had it. A check that cannot take the box added answers for the rise."""
    with_boxes = getattr(check, "with_boxes", None)
    if not callable(with_boxes):
        return "no collision check with the standing rod"
    with_rod = with_boxes([standing])
    for q in joint_line(q_retract, q_home):
        if with_rod(q, None):
            explain = getattr(with_rod, "explain", None)
            return f"the way home from the retract meets {explain(q) if callable(explain) else 'an obstacle'}"
    return ""


def rise_toward_home(
    spec: RobotSpec, q_retract: Array, q_home: Array, height_m: float, T_flange_tool: Array
) -> Array:
    """Where the rise after the retract ends when it goes on the straight joint line home: the first pose
    on it (:func:`joint_line`) with the tool tip ``height_m`` high, home itself if none is. The way home
    the task plans from there goes on along the same line."""
    q = joint_line(q_retract, q_home)
    high = np.nonzero(fk(spec, q, T_flange_tool)[:, 2, 3] >= height_m)[0]
    return q[int(high[0])].copy() if high.size else q_home.copy()
