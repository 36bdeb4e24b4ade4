"""The motion planner: direct path first, OMPL when it collides, then smoothing and timing.

:class:`MotionPlanner` turns a start configuration and a target — a joint goal, a tool
pose, a list of Cartesian poses, or waypoints with motion types — into a verified,
collision-free, time-parameterised :class:`JointTrajectory`, or raises the error that
says why not (InvalidInputError, IKFailureError, CollisionError,
PathPlanningTimeoutError, TrajectoryLimitError) with the offending value.

Pipeline for a joint-space move: validate → start/goal collision-free? → straight
joint path collision-free? → else OMPL (RRTConnect / RRTstar / PRM) + shortcutting →
timing (ruckig / TOPP-RA, verified against the limits) → the timed trajectory is
collision-checked once more at the set resolution (a smoothed curve can leave the
checked polyline); when it collides, the polyline is timed rest-to-rest instead.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from services.common.errors import (
    CollisionError,
    InvalidInputError,
    PathPlanningTimeoutError,
    TrajectoryLimitError,
)
from services.common.modes import MotionKind
from services.common.settings import MotionSettings
from services.kinematics.cartesian import cartesian_path
from services.kinematics.collision import CollisionChecker, Scene
from services.kinematics.interpolation import arc_lengths, densify, wrap_toward
from services.kinematics.model import ArmModel, Kinematics, check_pose, pose_text
from services.kinematics.trajectory import (
    Array,
    JointLimits,
    JointTrajectory,
    LimitReport,
    verify_trajectory,
)
from services.motion.corners import Corner, max_rounding, round_corner, with_corners
from services.motion.sampling import PLANNERS, plan_path, seed_planning
from services.motion.timing import moving_start, time_parameterize

log = logging.getLogger("pickplace.motion.planner")

LOCAL_MARGIN_RAD = 1.0  # first sampling box: the start–goal box grown by this on every joint
LOCAL_BUDGET_SHARE = 0.6  # share of the remaining budget the local attempt may use


@dataclass(frozen=True)
class PlannerConfig:
    planner: str = "RRTConnect"
    time_budget_s: float = 1.0
    collision_resolution_rad: float = math.radians(1.0)
    velocity_scale: float = 1.0
    acceleration_scale: float = 1.0
    knot_period_s: float = 0.01
    cartesian_step_m: float = 0.005
    cartesian_step_rad: float = math.radians(2.0)
    jump_threshold_rad: float = math.radians(10.0)
    min_manipulability: float = 1e-3
    timing: str = "auto"
    # before spline timing, polyline segments are split to at most this joint step so the
    # spline through them hugs the checked path
    spline_segment_rad: float = 0.25
    # OMPL's random seeds come from this one, so a process plans the same way on every run
    # (settings motion.seed); only the process's first planner sets it (OMPL's rule)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.planner not in PLANNERS:
            raise InvalidInputError(f"unknown planner {self.planner!r}; choose one of {sorted(PLANNERS)}")
        for name in (
            "time_budget_s",
            "collision_resolution_rad",
            "knot_period_s",
            "cartesian_step_m",
            "cartesian_step_rad",
            "jump_threshold_rad",
            "spline_segment_rad",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise InvalidInputError(f"planner setting {name} must be positive, got {v}")
        for name in ("velocity_scale", "acceleration_scale"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 < v <= 1):
                raise InvalidInputError(f"{name} must be within (0, 1], got {v}")

    @classmethod
    def from_settings(cls, m: MotionSettings) -> PlannerConfig:
        return cls(
            planner=m.planner,
            time_budget_s=m.planning_time_s,
            collision_resolution_rad=math.radians(m.collision_resolution_deg),
            velocity_scale=m.velocity_scale,
            acceleration_scale=m.acceleration_scale,
            knot_period_s=m.knot_period_s,
            cartesian_step_m=m.cartesian_step_m,
            cartesian_step_rad=math.radians(m.cartesian_step_deg),
            jump_threshold_rad=math.radians(m.jump_threshold_deg),
            min_manipulability=m.min_manipulability,
            seed=m.seed,
        )


@dataclass(frozen=True)
class Waypoint:
    """A target in a waypoint plan: a tool pose or joint positions, reached by a joint-space
    move (``joint``, MovJ-like, planned around obstacles) or a straight tool line (``linear``)."""

    pose: Array | None = None
    joints: Array | None = None
    motion: MotionKind = MotionKind.JOINT

    def __post_init__(self) -> None:
        if (self.pose is None) == (self.joints is None):
            raise InvalidInputError("a waypoint needs exactly one of a pose or joint positions")
        if self.motion not in (MotionKind.JOINT, MotionKind.LINEAR):
            raise InvalidInputError(f"waypoint motion must be 'joint' or 'linear', got {self.motion!r}")


@dataclass(frozen=True)
class PathPlan:
    """A checked joint path before timing (a blended run times its parts' paths together)."""

    path: Array  # the geometric joint waypoints, collision-checked
    planner: str  # "direct", "cartesian" or an OMPL planner name
    method: str  # how it is timed on its own (see services.motion.timing)
    planning_time_s: float


@dataclass
class Plan:
    trajectory: JointTrajectory
    path: Array  # the geometric joint waypoints the trajectory follows
    planner: str  # "direct", "cartesian", an OMPL planner name, or several joined by "+"
    planning_time_s: float
    timing_time_s: float
    notes: list[str] = field(default_factory=list)

    @property
    def goal(self) -> Array:
        return self.trajectory.positions[-1]


@dataclass(frozen=True)
class TrajectoryCheck:
    ok: bool
    message: str
    limits: LimitReport | None
    collision_time_s: float | None = None


# Joint paths are searched this much farther from the table and boxes than trajectories are checked.
SEARCH_CLEARANCE_M = 0.003


class MotionPlanner:
    """Plans for one arm in one scene. Not thread-safe (pinocchio data): one per request/thread."""

    def __init__(self, arm: ArmModel, scene: Scene | None = None, config: PlannerConfig | None = None):
        self.arm = arm
        self.config = config or PlannerConfig()
        seed_planning(self.config.seed)
        self.scene = scene or Scene()
        self.kin = Kinematics(arm)
        self.checker = CollisionChecker(arm, self.scene)
        self._search: CollisionChecker | None = None
        self.limits: JointLimits = JointLimits.from_spec(
            arm.spec, self.config.velocity_scale, self.config.acceleration_scale
        )
        # Dense straight-line IK paths: their third derivative is dominated by the IK step
        # discretisation, so a jerk limit would slow a 10 cm line to ~10 s. They are timed under
        # velocity and acceleration limits; the controller's servo filter smooths the rest.
        self.line_limits = dataclasses.replace(self.limits, max_jerk=None)
        self.names = arm.spec.joint_names

    # --- public entry points ------------------------------------------------------------------
    def plan_joints(self, start: ArrayLike, goal: ArrayLike, *, shortest_angle: bool = False) -> Plan:
        """Collision-free timed motion from ``start`` to the joint ``goal``.

        ``shortest_angle``: move full-turn joints to the goal's equivalent nearest the start
        (only where the joint's limits allow it).
        """
        return self.timed(self.joints_path(start, goal, shortest_angle=shortest_angle))

    def joints_path(self, start: ArrayLike, goal: ArrayLike, *, shortest_angle: bool = False) -> PathPlan:
        """The checked joint path of :meth:`plan_joints`, not yet timed."""
        t0 = time.perf_counter()
        deadline = t0 + self.config.time_budget_s
        q0 = self._valid_state(start, "start")
        q1 = self.limits.check_positions(goal, "goal")
        if shortest_angle:
            q1 = wrap_toward(q0, q1, self.limits.lower, self.limits.upper)
        self._require_free(q1, "goal")
        path, how = self._joint_path(q0, q1, deadline)
        return PathPlan(path, how, self.config.timing, time.perf_counter() - t0)

    def plan_to_pose(self, start: ArrayLike, T_base_tool: ArrayLike) -> Plan:
        """Collision-free timed motion to a tool pose (joint-space move to an IK solution).

        IK solutions are tried nearest-to-start first, skipping singular and colliding ones.
        """
        return self.timed(self.path_to_pose(start, T_base_tool))

    def path_to_pose(self, start: ArrayLike, T_base_tool: ArrayLike) -> PathPlan:
        """The checked joint path of :meth:`plan_to_pose`, not yet timed."""
        t0 = time.perf_counter()
        deadline = t0 + self.config.time_budget_s
        q0 = self._valid_state(start, "start")
        goal = self.goal_for_pose(check_pose(T_base_tool, "target pose"), q0)
        path, how = self._joint_path(q0, goal, deadline)
        return PathPlan(path, how, self.config.timing, time.perf_counter() - t0)

    def plan_cartesian(self, start: ArrayLike, targets: Sequence[ArrayLike]) -> Plan:
        """Straight tool lines from the start pose through ``targets`` (IK per step, jump check)."""
        return self.timed(self.line_path(start, targets))

    def line_path(self, start: ArrayLike, targets: Sequence[ArrayLike]) -> PathPlan:
        """The checked joint path of :meth:`plan_cartesian`, not yet timed."""
        t0 = time.perf_counter()
        q0 = self._valid_state(start, "start")
        path = self._cartesian(q0, targets)
        return PathPlan(path, "cartesian", "toppra_dense", time.perf_counter() - t0)

    def timed(self, p: PathPlan) -> Plan:
        """A checked path timed as its planner would (a trajectory that is verified and collision-free)."""
        notes: list[str] = []
        t1 = time.perf_counter()
        traj = self._timed(p.path, p.method, notes=notes)
        return Plan(traj, p.path, p.planner, p.planning_time_s, time.perf_counter() - t1, notes)

    def plan_waypoints(self, start: ArrayLike, waypoints: Sequence[Waypoint]) -> Plan:
        """A sequence of joint-space and linear moves; the arm stops at every waypoint.

        Stopping keeps each piece exactly on what was checked (and is how a MovJ/MovL list
        runs on the controller); use :meth:`plan_cartesian` for a continuous tool line.
        """
        t0 = time.perf_counter()
        if not waypoints:
            raise InvalidInputError("a waypoint plan needs at least one waypoint")
        q = self._valid_state(start, "start")
        traj = JointTrajectory.hold(self.names, q)
        paths = [q[None]]
        used: list[str] = []
        notes: list[str] = []
        timing_s = 0.0
        for k, wp in enumerate(waypoints):
            if not isinstance(wp, Waypoint):
                raise InvalidInputError(f"waypoint {k} is not a Waypoint: {wp!r}")
            if wp.motion == MotionKind.LINEAR:
                if wp.pose is not None:
                    target = check_pose(wp.pose, f"waypoint {k} pose")
                else:
                    assert wp.joints is not None  # a Waypoint holds exactly one of the two
                    target = self.kin.fk(self.limits.check_positions(wp.joints, f"waypoint {k} joints"))
                path = self._cartesian(q, [target])
                how = "cartesian"
                method = "toppra_dense"
            else:
                if wp.pose is not None:
                    goal = self.goal_for_pose(check_pose(wp.pose, f"waypoint {k} pose"), q)
                else:
                    assert wp.joints is not None  # a Waypoint holds exactly one of the two
                    goal = self.limits.check_positions(wp.joints, f"waypoint {k} joints")
                    self._require_free(goal, f"waypoint {k}")
                # the budget is for planning: time spent timing earlier pieces does not count
                spent = time.perf_counter() - t0 - timing_s
                path, how = self._joint_path(q, goal, time.perf_counter() + self.config.time_budget_s - spent)
                method = self.config.timing
            t1 = time.perf_counter()
            piece = self._timed(path, method, notes=notes)
            timing_s += time.perf_counter() - t1
            traj = traj.append(piece) if len(piece) > 1 else traj
            paths.append(path[1:])
            used.append(how)
            q = piece.positions[-1]
        plan_time = time.perf_counter() - t0
        return Plan(traj, np.vstack(paths), "+".join(used), plan_time - timing_s, timing_s, notes)

    def check_trajectory(self, traj: JointTrajectory, *, check_collisions: bool = True) -> TrajectoryCheck:
        """Limits (position, velocity, acceleration, jerk) and collisions of a given trajectory."""
        if traj.joint_names != self.names:
            return TrajectoryCheck(False, f"joint names {traj.joint_names} differ from {self.names}", None)
        try:
            # jerk is a smoothness target of the timing, not a hard limit: lines are timed without it
            report = verify_trajectory(traj, self.line_limits, at_rest=False)
        except TrajectoryLimitError as exc:
            return TrajectoryCheck(False, str(exc), None)
        if check_collisions:
            hit = self.checker.first_collision_in_trajectory(traj, self.config.collision_resolution_rad)
            if hit is not None:
                t, q = hit
                return TrajectoryCheck(
                    False, f"collision at t = {t:.3f} s: {self.checker.explain(q)}", report, t
                )
        return TrajectoryCheck(True, "within limits and collision-free", report)

    # --- pieces -------------------------------------------------------------------------------
    def _valid_state(self, q: ArrayLike, name: str) -> Array:
        qv = self.limits.check_positions(q, name)
        self._require_free(qv, name)
        return qv

    def _require_free(self, q: Array, name: str) -> None:
        if self.checker.in_collision(q):
            raise CollisionError(
                f"{name} configuration {np.round(q, 4).tolist()} rad is in collision: {self.checker.explain(q)}"
            )

    def goal_for_pose(self, T: Array, seed: Array) -> Array:
        """The joint goal for a tool pose: the in-limit, collision-free IK solution nearest ``seed``,
        non-singular if there is one. IKFailureError / CollisionError otherwise."""
        if self.kin.has_analytic_ik():
            candidates = list(self.kin.ik_analytic(T, seed))
        else:
            candidates = [self.kin.ik_numeric(T, seed)]
        if not candidates:
            from services.common.errors import IKFailureError

            raise IKFailureError(
                f"{self.arm.spec.name}: no inverse-kinematics solution within joint limits for the tool at "
                f"{pose_text(T)}"
            )
        free = [q for q in candidates if not self.checker.in_collision(q)]
        if not free:
            raise CollisionError(
                f"every IK solution for the tool at {pose_text(T)} is in collision "
                f"(nearest: {self.checker.explain(candidates[0])})"
            )
        good = [q for q in free if self.kin.manipulability(q) >= self.config.min_manipulability]
        return (good or free)[0]

    def _search_checker(self, q0: Array, q1: Array) -> CollisionChecker:
        """The checker joint paths are searched with: the scene padded SEARCH_CLEARANCE_M more than
        check_trajectory's, so a path that grazes an obstacle between its checked states (and the
        timed trajectory sampled elsewhere along it) does not come out; the nominal scene when an
        end of the move already lies inside that extra clearance."""
        if self._search is None:
            wider = dataclasses.replace(self.scene, padding_m=self.scene.padding_m + SEARCH_CLEARANCE_M)
            self._search = type(self.checker)(self.arm, wider)  # the same kind of checker, wider scene
        if self._search.in_collision(q0) or self._search.in_collision(q1):
            return self.checker
        return self._search

    def _joint_path(self, q0: Array, q1: Array, deadline: float) -> tuple[Array, str]:
        # paths are validated at half the trajectory-check resolution: the timed trajectory is
        # sampled at other points than the path was, and must still pass check_trajectory
        res = self.config.collision_resolution_rad / 2
        search = self._search_checker(q0, q1)
        if search.segment_free(q0, q1, res):
            return np.vstack([q0, q1]), "direct"
        hit = search.first_collision_on_segment(q0, q1, res)
        blocked = self.checker.explain(hit) if hit is not None else "an unknown contact"
        # sample near the start–goal box first (detours are usually local, and a small space is
        # found much faster, RRTstar above all), then in the whole joint range
        attempts = ((LOCAL_MARGIN_RAD, LOCAL_BUDGET_SHARE), (math.pi, 1.0))
        errors = []
        for margin, share in attempts:
            remaining = deadline - time.perf_counter()
            if remaining <= 1e-3:
                break
            try:
                path = plan_path(
                    lambda q: not search.in_collision(q),
                    self.limits,
                    q0,
                    q1,
                    planner=self.config.planner,
                    time_budget_s=remaining * share,
                    resolution_rad=res,
                    segment_free=lambda a, b: search.segment_free(a, b, res),
                    margin=margin,
                )
            except PathPlanningTimeoutError as exc:
                errors.append(f"within ±{margin:.2f} rad of the start/goal box: {exc}")
                continue
            return path, self.config.planner
        raise PathPlanningTimeoutError(
            f"no collision-free joint path within the {self.config.time_budget_s:.2f} s budget "
            f"({'; '.join(errors) or 'no time left to sample'}); the direct path is blocked by {blocked}"
        )

    def _cartesian(self, q0: Array, targets: Sequence[ArrayLike]) -> Array:
        c = self.config
        path = cartesian_path(
            self.kin,
            q0,
            targets,
            step_m=c.cartesian_step_m,
            step_rad=c.cartesian_step_rad,
            jump_threshold_rad=c.jump_threshold_rad,
        )
        hit = self.checker.first_collision_on_path(path, c.collision_resolution_rad / 2)
        if hit is not None:
            k, q = hit
            raise CollisionError(
                f"the straight tool line collides {k}/{path.shape[0] - 1} of the way, tool at "
                f"{pose_text(self.kin.fk(q))}: {self.checker.explain(q)}"
            )
        return path

    def _densify(self, path: Array) -> Array:
        return densify(path, self.config.spline_segment_rad)

    def _timed(self, path: Array, method: str, *, notes: list[str]) -> JointTrajectory:
        c = self.config
        if method == "toppra_dense":
            # a dense Cartesian path: the spline through its close points is the line itself
            try:
                traj = time_parameterize(
                    path, self.line_limits, self.names, dt=c.knot_period_s, method="toppra"
                )
            except TrajectoryLimitError as exc:
                notes.append(f"spline timing of the tool line failed ({exc}); stopping at every step instead")
                traj = time_parameterize(
                    path, self.limits, self.names, dt=c.knot_period_s, method="rest_to_rest"
                )
        else:
            src = self._densify(path) if path.shape[0] > 2 else path
            traj = time_parameterize(src, self.limits, self.names, dt=c.knot_period_s, method=method)
            if src is not path and traj.meta.get("method") == "rest_to_rest":
                # stopping at the densified points is pointless: stop at the real waypoints only
                traj = time_parameterize(
                    path, self.limits, self.names, dt=c.knot_period_s, method="rest_to_rest"
                )
        if traj.meta.get("on_polyline") == 1.0:
            return traj  # every path handed in here was collision-checked segment by segment
        hit = self.checker.first_collision_in_trajectory(traj, c.collision_resolution_rad)
        if hit is None:
            return traj
        notes.append(
            f"smoothed trajectory touched {self.checker.explain(hit[1])}; timed the checked polyline instead"
        )
        traj = time_parameterize(path, self.limits, self.names, dt=c.knot_period_s, method="rest_to_rest")
        return traj


# --- blending -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BlendPart:
    """One move of a blended run: the planner of its scene and options, and its checked joint path."""

    planner: MotionPlanner
    found: PathPlan  # from the end of the previous part to this move's goal
    line: bool  # a dense straight tool line (timed without the jerk limit, as plan_cartesian does)
    # how far the tool may leave the path where this part flows into the next (0: through its goal)
    corner_tolerance_m: float = 0.0

    @property
    def path(self) -> Array:
        return self.found.path


def _common_limits(parts: Sequence[BlendPart]) -> JointLimits:
    """The tightest of the parts' limits: the slowest move of the run bounds the whole blend."""
    lims = [p.planner.line_limits if any(q.line for q in parts) else p.planner.limits for p in parts]
    jerks = [lim.max_jerk for lim in lims if lim.max_jerk is not None]
    return dataclasses.replace(
        lims[0],
        max_velocity=np.min([lim.max_velocity for lim in lims], axis=0),
        max_acceleration=np.min([lim.max_acceleration for lim in lims], axis=0),
        max_jerk=np.min(jerks, axis=0) if len(jerks) == len(lims) else None,
    )


def _pass_times(traj: JointTrajectory, points: Sequence[Array]) -> list[float]:
    """When the trajectory passes each of ``points`` in order (the knot nearest each, searched
    forward from the previous one): the spline goes through every path point."""
    out, k0 = [], 0
    for q in points:
        d = np.max(np.abs(traj.positions[k0:] - q), axis=1)
        k0 += int(np.argmin(d))
        out.append(float(traj.times[k0]))
    return out


CORNER_ROUNDINGS_RAD = (0.3, 0.2, 0.12, 0.06)  # joint-space roundings tried at a corner, largest first
DEVIATION_STEP_RAD = 0.02  # joint step between the path's tool points a rounded corner is measured from
# of the tolerance, what the curve's samples may take: the spline timed through them strays a little
# further (0.5 mm seen on a 9 mm rounding)
DEVIATION_SHARE = 0.9
CURVE_STEP_RAD = 0.04  # between a rounded corner's samples: the timed spline through them keeps to the curve


def _tool_deviation(kin: Kinematics, curve: Array, original: Array) -> float:
    """How far the tool on ``curve`` comes from the tool on the ``original`` rows it replaces (the
    nearest of their tool points: an upper bound of the distance to the path between them)."""
    ref = np.array([kin.fk(q)[:3, 3] for q in densify(original, DEVIATION_STEP_RAD)])
    got = np.array([kin.fk(q)[:3, 3] for q in curve])
    return float(np.max(np.min(np.linalg.norm(got[:, None] - ref[None], axis=2), axis=1)))


def _round_corners(parts: Sequence[BlendPart], path: Array, corners: list[int]) -> list[Corner]:
    """Each inner corner whose part allows it rounded as far as it may: the largest rounding whose
    tool stays within the part's tolerance of the path and that is collision-free in the scenes of
    both moves it joins (the curve leaves the path each part was checked along)."""
    s = arc_lengths(path)
    out: list[Corner] = []
    for j, corner in enumerate(corners):
        tol = parts[j].corner_tolerance_m
        if tol <= 0.0:
            continue
        room = max_rounding(s, corners, j)
        kin, cfg = parts[j].planner.kin, parts[j].planner.config
        for d in CORNER_ROUNDINGS_RAD:
            found = round_corner(path, s, corner, min(d, room), CURVE_STEP_RAD)
            if found is None:
                break
            replaced = path[found.first - 1 : found.last + 2]
            if _tool_deviation(kin, found.curve, replaced) > DEVIATION_SHARE * tol:
                continue
            if any(
                p.planner.checker.first_collision_on_path(found.curve, cfg.collision_resolution_rad / 2)
                for p in (parts[j], parts[j + 1])
            ):
                continue
            out.append(found)
            break
    return out


def blend(
    parts: Sequence[BlendPart], split_period_s: float, start_velocity: Array | None = None
) -> tuple[list[JointTrajectory] | None, str]:
    """One time-optimal motion through the parts' joined paths, at rest only at its two ends (or from the
    joint velocity ``start_velocity`` at its start: the arm already moving along the first part), cut
    back into one trajectory per part (every inner one ends in motion; the cuts on multiples of
    ``split_period_s``, the period the driver streams at, so no streamed step is shortened).

    Where a part allows it, the corner at its goal is rounded first (:func:`_round_corners`); then the
    joined path is timed (TOPP-RA under the tightest part's limits, verified; through the waypoints
    exactly when the rounded path cannot be timed), and every part is collision-checked in its own
    scene along the timed motion. Returns the pieces and "", or None
    and why the blend was refused (the caller then stops at every waypoint).
    """
    first = parts[0].planner
    c = first.config
    rows = [parts[0].path[0][None]]
    for p in parts:
        rows.append((p.path if p.line else first._densify(p.path))[1:])
    path = np.vstack(rows)
    corners = [n - 1 for n in itertools.accumulate(len(r) for r in rows)][1:-1]  # each inner waypoint's row
    rounded = _round_corners(parts, path, corners)
    limits = _common_limits(parts)
    try:
        whole = time_parameterize(
            with_corners(path, rounded),
            limits,
            first.names,
            dt=c.knot_period_s,
            method="toppra",
            start_velocity=start_velocity,
        )
    except TrajectoryLimitError as exc:
        if not rounded:
            return None, f"blend not timed: {exc}"
        return _through_the_waypoints(parts, split_period_s, f"not timed ({exc})", start_velocity)
    cuts = _pass_times(whole, [p.path[-1] for p in parts[:-1]])
    period = split_period_s
    bounds = [0.0, *(min(round(t / period) * period, whole.duration) for t in cuts), whole.duration]
    if np.any(np.diff(bounds) <= 1e-6):
        return None, "blend: a part is shorter than one streaming period"
    pieces = [whole.window(a, b) for a, b in itertools.pairwise(bounds)]
    for k, (p, piece) in enumerate(zip(parts, pieces, strict=True)):
        hit = p.planner.checker.first_collision_in_trajectory(
            piece, p.planner.config.collision_resolution_rad
        )
        if hit is not None:
            what = f"touched {p.planner.checker.explain(hit[1])} in part {k}"
            if rounded:  # the spline timed through a curve strays a little from it
                return _through_the_waypoints(parts, split_period_s, what, start_velocity)
            return None, f"blended motion {what}"
    return pieces, ""


def _through_the_waypoints(
    parts: Sequence[BlendPart], split_period_s: float, why: str, start_velocity: Array | None
) -> tuple[list[JointTrajectory] | None, str]:
    """The blend again without rounded corners, after the rounded one failed for ``why``."""
    log.info("the blend with rounded corners %s: through the waypoints instead", why)
    return blend(
        [dataclasses.replace(p, corner_tolerance_m=0.0) for p in parts], split_period_s, start_velocity
    )


def time_runs(
    parts: Sequence[BlendPart | None],
    blends: Sequence[bool],
    split_period_s: float,
    start: Array,
    names: tuple[str, ...],
    start_velocity: Array | None = None,
) -> tuple[list[JointTrajectory], list[str]]:
    """One trajectory per waypoint, and notes: each run of moves joined by waypoints that ``blends``
    marks is timed as one blended motion cut into its parts (:func:`blend`), every other move on its
    own, and so is each move of a run that cannot be blended (it keeps its stops, noted). A blended
    part is never timed on its own. A None part (already there) holds where the arm is.

    ``start_velocity`` (nonzero): the arm is moving at ``start``; the first run is timed from that
    motion, as one blend even of a single move, or TrajectoryLimitError (it cannot stop at a waypoint
    it was not planned to stop at)."""
    start_velocity = moving_start(start_velocity, start.size)
    moving = start_velocity is not None
    pieces: list[JointTrajectory] = []
    notes: list[str] = []
    q = start
    k = 0
    while k < len(parts):
        end = k
        while end + 1 < len(parts) and blends[end] and parts[end] is not None and parts[end + 1] is not None:
            end += 1
        run = [p for p in parts[k : end + 1] if p is not None]
        blended: list[JointTrajectory] | None = None
        if moving and k == 0:
            if parts[0] is None:
                raise InvalidInputError("the arm is moving at the start: its first move cannot be none")
            blended, why = blend(run, split_period_s, start_velocity)
            if blended is None:
                raise TrajectoryLimitError(f"no motion from the arm's motion at the start: {why}")
        elif len(run) > 1:
            blended, why = blend(run, split_period_s)
            if blended is None:
                notes.append(f"waypoints {k}..{end} stop at every waypoint: {why}")
                log.info("waypoints %d..%d not blended: %s", k, end, why)
        if blended is not None:
            pieces += blended
            q = blended[-1].positions[-1]
        else:
            for part in parts[k : end + 1]:
                if part is None:
                    pieces.append(JointTrajectory.hold(names, q))
                    continue
                plan = part.planner.timed(part.found)
                notes += plan.notes
                pieces.append(plan.trajectory)
                q = plan.trajectory.positions[-1]
        k = end + 1
    return pieces, notes
