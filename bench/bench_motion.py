"""Motion figures: planning around an obstacle, trajectory generation (the IK figures are in
``bench_kinematics``).

Target (issue 3): planning around an obstacle median ≤ 10 ms. Times are wall-clock on whatever
else the machine is doing.
"""

from __future__ import annotations

import math
import time

import numpy as np

from services.common.errors import RobotError
from services.common.frames import make_transform
from services.kinematics.collision import Box, Scene
from services.kinematics.interpolation import min_jerk_keypose_trajectory
from services.kinematics.model import load_arm
from services.kinematics.robot_models import get_robot
from services.kinematics.trajectory import JointLimits
from services.motion.planner import MotionPlanner, PlannerConfig
from services.motion.timing import time_parameterize

DOWN = np.diag([1.0, -1.0, -1.0])


def _pick_place_queries(
    planner: MotionPlanner, rng: np.random.Generator, n: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(start joints at a pick pose, place tool pose) pairs: pick zone → drop zones across the wall."""
    home = np.deg2rad([0, 0, 90, 0, -90, 0])
    out = []
    while len(out) < n:
        pick = make_transform(
            DOWN, [rng.uniform(0.35, 0.60), rng.uniform(-0.25, 0.25), rng.uniform(0.03, 0.12)]
        )
        place = make_transform(
            DOWN, [rng.uniform(0.28, 0.50), rng.uniform(0.42, 0.50), rng.uniform(0.03, 0.12)]
        )
        try:
            q_pick = planner.goal_for_pose(pick, home)
            planner.goal_for_pose(place, q_pick)  # reachable without touching the wall
        except RobotError:
            continue
        out.append((q_pick, place))
    return out


def bench_planning(n: int = 120) -> None:
    arm = load_arm("nova5")
    # the twin's wall between the pick zone and the red/blue drop zones, raised to 0.25 m so that
    # most straight joint paths hit it
    wall = Box((0.30, 0.315, 0.0), (0.50, 0.365, 0.25), "wall")
    planner = MotionPlanner(arm, Scene(boxes=(wall,), padding_m=0.01), PlannerConfig(time_budget_s=1.0))
    queries = _pick_place_queries(planner, np.random.default_rng(3), n)
    res = math.radians(1.0)
    plan_t, timing_t, ok, sampled, blocked = [], [], 0, 0, 0
    durations = []
    for q_pick, place in queries:
        try:
            goal = planner.goal_for_pose(place, q_pick)
        except RobotError:
            continue
        blocked += not planner.checker.segment_free(q_pick, goal, res)
        t0 = time.perf_counter()
        try:
            plan = planner.plan_to_pose(q_pick, place)
        except RobotError as exc:
            print(f"    failed: {type(exc).__name__}: {str(exc)[:120]}")
            plan_t.append(time.perf_counter() - t0)
            continue
        ok += 1
        sampled += plan.planner != "direct"
        plan_t.append(plan.planning_time_s)
        timing_t.append(plan.timing_time_s)
        durations.append(plan.trajectory.duration)
    a = np.asarray(plan_t) * 1e3
    b = np.asarray(timing_t) * 1e3
    print(
        f"planning, Nova5, {len(plan_t)} pick→place queries across a 0.25 m wall (RRTConnect, 1° resolution):"
    )
    print(f"  success {ok}/{len(plan_t)}; straight path blocked in {blocked}, sampled (OMPL) in {sampled}")
    print(
        f"  planning (IK + collision checks + OMPL + shortcutting): median {np.median(a):.1f} ms, "
        f"p95 {np.percentile(a, 95):.1f} ms, max {a.max():.1f} ms"
    )
    print(
        f"  trajectory generation (smoothing + timing + verification + final collision check): "
        f"median {np.median(b):.1f} ms, p95 {np.percentile(b, 95):.1f} ms; motion duration median "
        f"{np.median(durations):.2f} s"
    )


def bench_trajectories() -> None:
    spec = get_robot("nova5")
    lim = JointLimits.from_spec(spec)
    names = spec.joint_names
    poses = np.deg2rad(
        [
            [0, 0, 90, 0, -90, 0],
            [30, 20, 80, -10, -90, 0],
            [30, 30, 80, -20, -90, 0],
            [30, 20, 80, -10, -90, 0],
            [-30, 20, 80, -10, -90, 0],
            [-30, 30, 80, -20, -90, 0],
            [-30, 20, 80, -10, -90, 0],
            [0, 0, 90, 0, -90, 0],
        ]
    )
    rng = np.random.default_rng(4)
    time_parameterize(poses[:3], lim, names)  # warm up (imports)

    def timed(fn, reps: int) -> float:  # type: ignore[no-untyped-def]
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        return (time.perf_counter() - t0) / reps * 1e3

    kp = timed(lambda: min_jerk_keypose_trajectory(poses, 2.0, 0.5, joint_names=names, limits=lim), 200)
    two = timed(lambda: time_parameterize(poses[:2] + rng.normal(0, 0.01, (2, 6)), lim, names), 50)
    five = timed(lambda: time_parameterize(poses[:5] + rng.normal(0, 0.01, (5, 6)), lim, names), 20)
    five_nj = timed(
        lambda: time_parameterize(
            poses[:5] + rng.normal(0, 0.01, (5, 6)), JointLimits.from_spec(spec, jerk=False), names
        ),
        20,
    )
    print("trajectory generation (Nova5, verified against the limits):")
    print(f"  min-jerk key-pose cycle, 8 poses with dwell: {kp:.2f} ms")
    print(f"  straight move, ruckig (jerk-limited): {two:.1f} ms")
    print(f"  5-waypoint path, jerk-limited (best of TOPP-RA+filter / stop-at-waypoints): {five:.1f} ms")
    print(f"  5-waypoint path, TOPP-RA velocity/acceleration only: {five_nj:.1f} ms")


def main() -> None:
    bench_planning()
    bench_trajectories()


if __name__ == "__main__":
    main()
