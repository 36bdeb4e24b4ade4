"""PLAN: from what vision saw to a pick under way — the scene's obstacles, the place spot, the grasp plan
with its way home, and the motions to its first stop planned while the rest plans in the background.

Pure orchestration over the grasp and motion ports (no I/O of its own); the cycle (services.task.cycle)
decides when to plan, what to do when planning fails, and executes what this returns."""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from services.common.errors import PlanningError, RobotError
from services.common.modes import GripperCommand, MotionKind, TaskKind
from services.kinematics.trajectory import JointTrajectory
from services.task.cycle_config import CycleConfig
from services.task.grasp_offsets import order_offsets
from services.task.moves import (
    above_pose,
    blends,
    box_around,
    grasp_approach,
    horizontal,
    joined,
    move_to,
    object_id,
    park_pose,
    pose_list,
    pre_grasp_at,
    rod_box,
    rounds,
    safe_home_of,
    with_way_home,
    without_safe_home,
)
from services.task.pacing import LINE_PACE, TOOL_ACCELERATION_M_S2, LinePace, paced_on_line
from services.task.placement import free_place_xy, place_candidates
from services.task.planned import PlannedPick
from services.task.ports import (
    ArmView,
    GraspPlan,
    GraspPort,
    MotionPort,
    Move,
    Observation,
    PlannedWaypoint,
    SeenBox,
    SeenCube,
    SeenRod,
)
from services.task.states import PickOutcome

log = logging.getLogger("pickplace.task.planning")

RESUME_TOLERANCE_RAD = np.deg2rad(0.5)
SET_OFF = "SET_OFF"  # the move toward the object while its grasp plans
OBJECT_MARGIN_M = 0.0  # the motion scene pads every box already (motion.padding_m)


@dataclass(frozen=True)
class SetOffMove:
    """The move toward the object while its grasp plans, and the scene it was planned in (everything
    seen, the object too)."""

    traj: JointTrajectory
    scene: tuple[SeenBox, ...]
    # it ends where the first grasp option's approach starts (a rod's: the jaws across it), so the plan
    # may go straight down from there; a cube's set-off keeps the jaws as they are (its faces are not
    # known here), and its plan turns them first
    on_approach: bool = False


class PickPlanning:
    """Plans picks for one cell: its grasp and motion planners, the cycle's configuration and the
    camera's view of the pick zone (None: only the safe home leaves it clear)."""

    def __init__(self, grasp: GraspPort, motion: MotionPort, config: CycleConfig, view: ArmView | None):
        self.grasp, self.motion, self.config, self.view = grasp, motion, config, view

    async def set_off(self, task: TaskKind, obs: Observation, q: np.ndarray) -> SetOffMove | None:
        """A joint move from ``q`` to above the object the first option picks (``set_off_height_m`` above
        its centre, the tool straight down, the jaws across a rod the way round nearer their turn at ``q``),
        clear of everything seen, that object included; None when there is none (the arm then waits for
        the plan where it is). The grasp plans meanwhile: it never depends on where the arm is."""
        height = self.config.set_off_height_m
        if (
            height <= 0
            or (task is TaskKind.STAND_ROD and not obs.rods)
            or (task is TaskKind.SORT_CUBES and not obs.cubes)
        ):
            return None
        R_now = (await self.motion.tool_pose(q))[:3, :3]
        if task is TaskKind.STAND_ROD:  # the jaws across the rod, above where its first option grasps it
            rod = obs.rods[0]
            offset = self._rod_offsets(rod, self._obstacles(obs, q, None))[0]
            T = above_pose(rod.center + offset * horizontal(rod.axis), height, R_now, across=rod.axis)
        else:  # the jaws turned as they are: the cube's faces are not known here
            T = above_pose(obs.cubes[0].centroid, height, R_now)
        everything = (
            self.not_the_arm(obs.obstacles, q)
            + tuple(box_around(c.centroid, c.size / 2 + OBJECT_MARGIN_M) for c in obs.cubes)
            + tuple(rod_box(r) for r in obs.rods)
        )
        try:
            traj = await self.single(q, Move(MotionKind.JOINT, T, label=SET_OFF), everything)
        except RobotError as exc:  # no way there: the arm waits for the plan where it is
            log.info("no set-off move above the object (%s): waiting for the plan at rest", exc)
            return None
        home = self.config.home_joints
        if traj is not None and home is not None and not same_branch(traj.positions[-1], np.asarray(home)):
            # the grasp plans its joints in the safe home's branch: an arm parked elsewhere (the twin's
            # first pose, turned half round from home) reached the pose above the rod with the elbow the
            # other way, and went back round for the pre-grasp (6.6 + 2.5 s instead of 0.9 s)
            log.info("the pose above the object is in another arm branch than the safe home: not set off")
            return None
        return SetOffMove(traj, everything, task is TaskKind.STAND_ROD) if traj is not None else None

    async def way_on(
        self, planned: PlannedPick, set_off: SetOffMove, q: np.ndarray, qd: np.ndarray
    ) -> tuple[JointTrajectory, int] | None:
        """The rest of the set-off and the grasp line as one motion from the arm moving at ``q`` with joint
        velocity ``qd`` on its way, and the grasp waypoint it ends at; None when the plan does not go
        straight down its approach from where the set-off ends (it stops or moves elsewhere first: a
        cube's plan turns the jaws to its faces, and a way on through that turn was seen to take
        0.15-0.23 s to plan on a busy machine and then not to be timeable), or no such motion is found
        (the set-off then ends at rest as planned). The rest of the set-off keeps its scene (the object
        too); the corner above the object is rounded within the cycle's tolerance, checked in the scenes
        of both moves it joins. The jaws must be open already."""
        plan, end = planned.plan, set_off.traj.positions[-1]
        g = next((i for i, w in enumerate(plan.waypoints) if w.gripper is GripperCommand.CLOSE), None)
        if g is None or not grasp_approach(plan, g) or not all(blends(plan, i) for i in range(g)):
            return None
        for i in range(g):  # every move before the grasp line ends where the set-off does (the pre-grasp)
            m = move_to(plan, i)
            if m is not None and not (
                m.kind is MotionKind.JOINT and m.target.ndim == 1 and near(m.target, end)
            ):
                return None
        line = move_to(plan, g)
        if line is None:
            return None
        rest = Move(
            MotionKind.JOINT,
            end,
            label=SET_OFF,
            blend=True,
            blend_tolerance_m=self.config.corner_tolerance_m,
            obstacles=set_off.scene,
        )
        moves = [rest, replace(line, blend=False, blend_tolerance_m=0.0)]
        try:
            planned_moves = await self.motion.plan_moves(q, moves, planned.obstacles, qd)
        except RobotError as exc:
            log.info("no way on from the set-off to the grasp without a stop: %s", exc)
            return None
        trajs = [t for t in planned_moves if t is not None]
        if len(trajs) != len(moves):
            return None
        way = trajs[0]
        for t in trajs[1:]:
            way = joined(way, t)
        return way, g

    async def plan(
        self,
        task: TaskKind,
        obs: Observation,
        out: PickOutcome,
        alternative: int,
        q: np.ndarray,
        seen_from: np.ndarray | None = None,
    ) -> PlannedPick:
        """The ``alternative``-th option for an object of ``obs`` with the arm at ``q``; records the
        object, the grasp and the poses on ``out``. A rod: the first one, grasped at the offsets along it in
        turn. Cubes: each seen cube in turn (one that cannot be picked now, hemmed in by its neighbours,
        waits until they are sorted), then each one's next-best grasp. ``seen_from``: where the arm stood
        for the picture when it has set off since (it then goes from ``q`` straight to the pre-grasp)."""
        target_cube = (
            obs.cubes[alternative % len(obs.cubes)] if task is TaskKind.SORT_CUBES and obs.cubes else None
        )
        obstacles = self._obstacles(obs, q if seen_from is None else seen_from, target_cube)
        rod: SeenRod | None = None
        offset = 0.0
        if task is TaskKind.STAND_ROD:
            rod = obs.rods[0]
            place = self._place(replace(obs, obstacles=obstacles))
            offsets = self._rod_offsets(rod, obstacles)
            offset = offsets[alternative % len(offsets)]
            # once every offset failed on the cheapest IK branches, costlier branches may be taken too
            plan = await self.grasp.plan_rod(
                rod,
                q,
                obstacles,
                alternative // len(offsets),
                place,
                offset,
                other_branches=alternative >= len(offsets),
            )
            out.object_id = object_id(rod)
        else:
            if target_cube is None:
                raise PlanningError("no cube to sort")
            cube = target_cube
            plan = await self.grasp.plan_cube(cube, q, obstacles, alternative // len(obs.cubes))
            out.object_class = f"cube_{cube.color}"
            out.object_id = f"cube@{cube.centroid[0]:.3f},{cube.centroid[1]:.3f}"
        out.grasp_quality = plan.quality
        grasp_wp = next((w for w in plan.waypoints if w.gripper is GripperCommand.CLOSE), plan.waypoints[0])
        out.pick_pose = pose_list(grasp_wp.T_base_tool)
        out.place_pose = [*map(float, plan.place_position), 0.0, 0.0, 0.0, 1.0]
        home = safe_home_of(plan)
        if home is not None and not near(q, home) and (seen_from is not None or self.clear(q)):
            # out of the camera's view already, or on the way to the object: straight to the pre-grasp
            plan = without_safe_home(plan)
        if seen_from is not None:  # set off: where that move ends may be on the approach already
            plan = pre_grasp_at(plan, q, await self.motion.tool_pose(q))
        if home is not None:
            # back only as far as the first pose that leaves the camera's view clear for the next look
            end = plan.waypoints[-1].joints
            park = (
                park_pose(end, home, lambda q: self.clear(q) and not self.touches(q, obstacles))
                if self.view is not None
                else home
            )
            plan = with_way_home(plan, park)
        # the arm sets off as soon as the moves to its first stop are planned; the rest up to the
        # touch-down plans meanwhile (and what follows a touch-down plans from where it touched)
        n = len(plan.waypoints)
        first_stop = next(
            (i for i in range(n) if move_to(plan, i) is not None and not blends(plan, i)), n - 1
        )
        trajs = await self.motions(plan, range(first_stop + 1), q, obstacles)
        planned = PlannedPick(plan, trajs, obstacles, rest_from=n, home=home, rod=rod, grasp_offset_m=offset)
        if first_stop + 1 < n:
            guarded = next(
                (i for i in range(first_stop + 1, n) if plan.waypoints[i].guard_force_n > 0), n - 1
            )
            q_stop = next((t.positions[-1] for t in reversed(trajs) if t is not None), q)
            planned.plan_rest(
                first_stop + 1, self.motions(plan, range(first_stop + 1, guarded + 1), q_stop, obstacles)
            )
        return planned

    def _place(self, obs: Observation) -> np.ndarray | None:
        """Where to stand the rod: the configured spot or the nearest free one (None: the grasp service's)."""
        if self.config.place_xy is None:
            return None
        cands = place_candidates(
            np.asarray(self.config.place_xy),
            np.asarray(self.config.place_region_min),
            np.asarray(self.config.place_region_max),
        )
        place = free_place_xy(obs, cands, self.config.place_clearance_m)
        if place is None:
            raise PlanningError(
                f"no free spot to stand the rod near {self.config.place_xy} "
                f"({len(cands)} candidates, clearance {self.config.place_clearance_m} m)"
            )
        return place

    async def motions(
        self, plan: GraspPlan, indices: range, start: np.ndarray, obstacles: tuple[SeenBox, ...]
    ) -> list[JointTrajectory | None]:
        """The trajectories to the waypoints ``indices`` (None elsewhere) from ``start``, planned in one
        request; a guarded approach is slowed to the grasp plan's touch-down speed."""
        moves = {i: m for i in indices if (m := move_to(plan, i)) is not None}
        last = max(moves, default=-1)
        tolerance = self.config.corner_tolerance_m
        moves = {
            i: replace(
                m,
                blend=i != last and blends(plan, i),
                blend_tolerance_m=tolerance if i != last and rounds(plan, i) else 0.0,
            )
            for i, m in moves.items()
        }
        planned = await self.motion.plan_moves(start, list(moves.values()), obstacles)
        if len(planned) != len(moves):
            raise PlanningError(f"the motion planner answered {len(planned)} of {len(moves)} moves")
        trajs: list[JointTrajectory | None] = [None] * len(plan.waypoints)
        q = start
        for i, traj in zip(moves, planned, strict=True):
            if traj is None:
                continue
            trajs[i] = await self._paced(plan.waypoints[i], moves[i], traj, q)
            q = traj.positions[-1]
        return trajs

    async def _paced(
        self, w: PlannedWaypoint, move: Move, traj: JointTrajectory, start: np.ndarray
    ) -> JointTrajectory:
        if w.guard_force_n > 0 and w.guard_speed_m_s > 0:
            p0 = (await self.motion.tool_pose(start))[:3, 3]
            if w.guard_slow_band_m > 0 and w.guard_approach_speed_m_s > w.guard_speed_m_s:
                # two-stage: fast down to the band above the nominal contact, slow through it
                along = np.asarray(w.guard_direction, dtype=float)
                band_from = float(np.dot(w.T_base_tool[:3, 3] - p0, along)) - w.guard_slow_band_m
                along_line = [
                    float(np.dot((await self.motion.tool_pose(q))[:3, 3] - p0, along)) for q in traj.positions
                ]
                paced = paced_on_line(
                    traj,
                    np.asarray(along_line),
                    w.guard_approach_speed_m_s,
                    w.guard_speed_m_s,
                    band_from,
                    max_joint_acceleration=self.config.max_joint_acceleration,
                )
                # the caps it went under, for the eval's bound (services.task.recording)
                paced.meta[LINE_PACE] = LinePace(
                    w.guard_approach_speed_m_s, w.guard_speed_m_s, band_from, TOOL_ACCELERATION_M_S2
                )
                return paced
            # a guarded approach goes no faster than the grasp plan's touch-down speed
            dist = float(np.linalg.norm(move.target[:3, 3] - p0))
            needed = dist / w.guard_speed_m_s
            if traj.duration < needed:
                traj = traj.scaled(needed / traj.duration)
        return traj

    async def further_touch_down(
        self, plan: GraspPlan, i: int, start: np.ndarray, obstacles: tuple[SeenBox, ...], extension_m: float
    ) -> JointTrajectory | None:
        """The guarded touch-down to waypoint ``i`` gone on ``extension_m`` past its overtravel from
        ``start`` (where it ended without feeling the contact), in its own scene, slow all the way."""
        move = move_to(plan, i, further_m=extension_m)
        w = plan.waypoints[i]
        if move is None or w.guard_force_n <= 0:
            raise PlanningError(f"{w.name} is not a guarded touch-down")
        further = replace(move, label=f"{w.name}_FURTHER")
        traj = await self.single(start, further, obstacles)
        if traj is None:
            return None
        # at the touch-down speed from the first millimetre: the contact is due at any moment
        return await self._paced(replace(w, guard_slow_band_m=0.0), further, traj, start)

    async def single(
        self, start: np.ndarray, move: Move, obstacles: tuple[SeenBox, ...]
    ) -> JointTrajectory | None:
        (traj,) = await self.motion.plan_moves(start, [move], obstacles)
        return traj

    def _obstacles(
        self, obs: Observation, q_seen: np.ndarray, target_cube: SeenCube | None
    ) -> tuple[SeenBox, ...]:
        """Everything on the table that is not the target (``target_cube``, or the first rod): an
        obstacle for the carried object too. ``q_seen``: where the arm stood for the picture."""
        return (
            self.not_the_arm(obs.obstacles, q_seen)
            + tuple(
                box_around(c.centroid, c.size / 2 + OBJECT_MARGIN_M)
                for c in obs.cubes
                if c is not target_cube
            )
            + tuple(box_around(r.center, r.length / 2 + OBJECT_MARGIN_M) for r in obs.rods[1:])
        )

    def _rod_offsets(self, rod: SeenRod, obstacles: tuple[SeenBox, ...]) -> tuple[float, ...]:
        """Where along the rod to grasp it, in the order to try: the options of recovery too (a neighbour
        may block the fingers at its centre; the twin notes show ±50 mm off-centre still stands the rod,
        and ±75 mm (pads 14 mm inside the end) was seen to stand it in eval)."""
        cfg = self.config
        return order_offsets(
            cfg.grasp_offsets_m, rod.center, rod.axis, obstacles, *cfg.jaw_footprint_m, cfg.jaw_clearance_m
        )

    def not_the_arm(self, boxes: tuple[SeenBox, ...], q: np.ndarray) -> tuple[SeenBox, ...]:
        """The boxes vision saw, without those that are the arm itself where it stood for the picture. At
        the safe home too: under a camera mounted a few tenths of a degree off, the top rows of the image
        catch the elbow there, and vision stands what it sees at the image edge on the table (seed 1706:
        a 0.39 m column beside the rod refused all its grasps)."""
        view = self.view
        if view is None:
            return boxes
        kept = tuple(b for b in boxes if not view.holds_arm(q, b.min, b.max))
        if len(kept) < len(boxes):
            log.info("%d seen obstacle(s) are the arm itself: left out", len(boxes) - len(kept))
        return kept

    def touches(self, q: np.ndarray, boxes: tuple[SeenBox, ...]) -> bool:
        """Whether the arm at ``q`` reaches into a seen box (or close around it). Parked there, the next
        picture would take the box for the arm itself and leave it out of the plan (the wall beside the
        sort-cubes drop zone, left out so, was hit by the fingers on the next approach)."""
        view = self.view
        return view is not None and any(view.holds_arm(q, b.min, b.max) for b in boxes)

    def clear(self, q: np.ndarray) -> bool:
        """Whether the arm at ``q`` leaves the camera's view of the pick zone clear (by the camera model)."""
        return self.view is not None and bool(self.view.clear(np.asarray(q, dtype=float)))


def same_branch(q: np.ndarray, ref: np.ndarray) -> bool:
    """Whether the elbow (joint 3) and the wrist (joint 5) bend the same way at ``q`` as at ``ref``."""
    return bool(np.sign(q[2]) == np.sign(ref[2]) and np.sign(q[4]) == np.sign(ref[4]))


def near(q: np.ndarray, target: np.ndarray | tuple[float, ...] | None) -> bool:
    """The arm is at ``target`` within the tracking error a finished motion leaves."""
    if target is None:
        return False
    return bool(np.max(np.abs(np.asarray(q) - np.asarray(target))) <= RESUME_TOLERANCE_RAD)
