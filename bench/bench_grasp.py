"""Grasp service figures: planning time, feasibility over the pick zone, and plans run in the twin.

1. ε / force-closure cost and ComputeGrasps time per shape.
2. Rod pick-and-stand planning over seeded random rods in the pick zone (with the motion
   collision checker and the seed-004 wall): feasible fraction, planning time p50/p95, lift and
   the smallest rod-end clearance during the turn.
3. Cube pick-and-place planning per colour.
4. Rod plans executed in the MuJoCo twin (ground-truth rod pose = perfect perception; the twin's
   contact physics; guarded touch-down from the wrist force): stand success, slip, tilt.
"""

from __future__ import annotations

import math
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from services.common.modes import GripperCommand, MotionKind
from services.common.settings import Settings, load_settings
from services.grasp.collision import MotionCollisionCheck
from services.grasp.cube import CubeObservation, plan_pick_and_place
from services.grasp.force_closure import ContactModel, evaluate_force_closure
from services.grasp.geometry import pose, rotation_z
from services.grasp.plan import PickPlan
from services.grasp.rod import RodObservation, plan_pick_and_stand
from services.grasp.synthesis import ObjectSpec, compute_grasps
from services.kinematics.collision import Box
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_geometry

Array = np.ndarray


def _pct(xs: list[float], unit: str = "ms", scale: float = 1e3) -> str:
    a = np.asarray(xs) * scale
    return f"p50 {np.percentile(a, 50):.1f} {unit}, p95 {np.percentile(a, 95):.1f} {unit}, max {a.max():.1f} {unit}"


def _wall(settings: Settings) -> list[Box]:
    sc = settings.sim.twin.scene
    c, h = np.array(sc.obstacle_center_m), np.array(sc.obstacle_half_size_m)
    return [Box(tuple(c - h), tuple(c + h), "wall")]


def rod_from_twin(engine: object, name: str = "rod") -> RodObservation:
    """The rod as perfect perception would report it (twin ground truth)."""
    from services.sim.twin import ground_truth as gt

    T = gt.object_pose(engine, name)  # type: ignore[arg-type]
    obj = engine.scene.get(name)  # type: ignore[attr-defined]
    return RodObservation.create(T[:3, 3], T[:3, 2], obj.size_m[2], obj.size_m[0])


def execute_plan_in_twin(engine: object, plan: PickPlan) -> dict[str, float]:
    """Run a waypoint plan on the twin the way the task would: joint moves to the planned joints,
    straight tool lines (dense IK, same branch), the guarded descent stopping on a wrist-force
    drop, gripper actions after each waypoint. Returns intermediate metrics."""
    from services.sim.twin import ground_truth as gt
    from services.sim.twin.trial import ScriptedArm

    arm = ScriptedArm(engine)  # type: ignore[arg-type]
    out: dict[str, float] = {"touch_detected": 0.0, "slip_mm": 0.0, "slip_deg": 0.0}
    T_ref: Array | None = None
    for w in plan.waypoints:
        if w.motion == MotionKind.JOINT:
            arm.move_joints(w.q, max(0.8, float(np.max(np.abs(w.q - arm.q))) / 1.2))
        elif w.motion == MotionKind.LINEAR:
            T0 = arm.tool_pose()
            dist = float(np.linalg.norm(w.T_base_tool[:3, 3] - T0[:3, 3]))
            cosang = (np.trace(T0[:3, :3].T @ w.T_base_tool[:3, :3]) - 1) / 2
            ang = math.acos(float(np.clip(cosang, -1.0, 1.0)))
            if w.guard is None:
                arm.move_linear(w.T_base_tool, max(0.4, dist / 0.15, ang / 1.0))
            else:
                arm.wait(0.2)
                fz_ref = arm.last.tcp_force[2]
                T_end = w.T_base_tool.copy()
                T_end[:3, 3] += w.guard.overtravel_m * np.asarray(w.guard.direction)
                dist = float(np.linalg.norm(T_end[:3, 3] - T0[:3, 3]))
                drop = w.guard.force_drop_n
                touched = arm.move_linear(
                    T_end,
                    dist / w.guard.speed_m_s,
                    stop=lambda s, ref=fz_ref, drop=drop: s.tcp_force[2] - ref > drop,  # type: ignore[misc]
                )
                out["touch_detected"] = float(touched)
                out["tilt_before_release_deg"] = gt.axis_tilt_deg(gt.object_pose(engine, "rod"))  # type: ignore[arg-type]
        if w.gripper is not None:
            arm.set_gripper(
                w.gripper == GripperCommand.CLOSE, wait_s=0.6 if w.gripper == GripperCommand.CLOSE else 0.5
            )
            if w.gripper == GripperCommand.CLOSE:
                T_ref = gt.T_tool_object(engine, "rod")  # type: ignore[arg-type]
        if T_ref is not None and w.holding and w.gripper is None:
            mm, deg = gt.slip(T_ref, gt.T_tool_object(engine, "rod"))  # type: ignore[arg-type]
            out["slip_mm"], out["slip_deg"] = max(out["slip_mm"], mm), max(out["slip_deg"], deg)
    out["sim_time_s"] = float(engine.time_s)  # type: ignore[attr-defined]
    return out


def _force_closure_cost() -> None:
    model = ContactModel(0.5, 8, 0.005)
    pts = np.array([[x, s * 0.011, 0.0] for s in (1, -1) for x in (-0.011, 0.011)])
    nrm = np.array([[0.0, -s, 0.0] for s in (1, -1) for _ in range(2)])
    t = []
    for _ in range(50):
        t0 = time.perf_counter()
        res = evaluate_force_closure(pts, nrm, model, 0.1)
        t.append(time.perf_counter() - t0)
    print(f"force closure (2 line contacts, 8-edge cones, soft): eps {res.epsilon:.4f}; {_pct(t)}")


def _compute_grasps(settings: Settings) -> None:
    spec = get_robot(settings.robot.model)
    T_ft = tool_geometry(settings).T_flange_tool()
    home = np.radians(settings.grasp.safe_home_joints_deg[spec.name])
    R_lying = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    objs = {
        "cylinder (lying rod)": ObjectSpec.from_request(
            "cylinder", pose(R_lying, [0.45, 0.0, 0.011]), 0.022, 0, 0.2
        ),
        "box (50 mm cube)": ObjectSpec.from_request(
            "box", pose(rotation_z(0.3), [0.5, -0.1, 0.025]), 0.05, 0.05, 0.05
        ),
        "sphere (60 mm)": ObjectSpec.from_request("sphere", pose(np.eye(3), [0.5, 0.1, 0.03]), 0.06, 0, 0),
    }
    check = MotionCollisionCheck.from_settings(settings, _wall(settings))
    for name, obj in objs.items():
        t = []
        for _ in range(5):
            t0 = time.perf_counter()
            res = compute_grasps(obj, spec, T_ft, home, settings.grasp, settings.gripper.stroke_m, check)
            t.append(time.perf_counter() - t0)
        best = res.grasps[0] if res.grasps else None
        print(
            f"ComputeGrasps {name}: {res.summary()}; best quality {best.quality if best else 0:.3f} "
            f"eps {best.epsilon if best else 0:.4f}; {_pct(t)}"
        )


def _rod_planning(settings: Settings, n: int = 100) -> None:
    spec = get_robot(settings.robot.model)
    T_ft = tool_geometry(settings).T_flange_tool()
    home = np.radians(settings.grasp.safe_home_joints_deg[spec.name])
    check = MotionCollisionCheck.from_settings(settings, _wall(settings))
    sc = settings.sim.twin.scene
    rng = np.random.default_rng(2024)
    t, lifts, clear, fails = [], [], [], []
    wall = _wall(settings)[0]
    lo, hi = np.asarray(wall.min)[:2] - sc.min_gap_m, np.asarray(wall.max)[:2] + sc.min_gap_m
    rods: list[RodObservation] = []
    while len(rods) < n:  # like the twin's scenes: the rod keeps min_gap from the wall
        x, y = (
            rng.uniform(sc.pick_zone_min_m[0], sc.pick_zone_max_m[0]),
            rng.uniform(sc.pick_zone_min_m[1], sc.pick_zone_max_m[1]),
        )
        yaw = rng.uniform(-np.pi, np.pi)
        a = np.array([np.cos(yaw), np.sin(yaw)])
        pts = np.array([x, y]) + np.linspace(-0.5, 0.5, 11)[:, None] * sc.rod_length_m * a
        if np.any(np.all((pts > lo) & (pts < hi), axis=1)):
            continue
        rods.append(
            RodObservation.create(
                [x, y, sc.rod_diameter_m / 2], [a[0], a[1], 0.0], sc.rod_length_m, sc.rod_diameter_m
            )
        )
    for rod in rods:
        t0 = time.perf_counter()
        try:
            p = plan_pick_and_stand(
                spec,
                rod,
                home,
                settings.grasp,
                T_ft,
                settings.gripper.stroke_m,
                q_home=home,
                collision_check=check,
            )
            lifts.append(float(p.notes["lift_m"]))
            clear.append(float(p.notes["min_rod_clearance_m"]))
        except Exception as exc:
            fails.append(f"{type(exc).__name__}: {str(exc)[:120]}")
        t.append(time.perf_counter() - t0)
    print(
        f"rod pick-and-stand planning, {n} random rods in the pick zone (with collision checks): "
        f"{n - len(fails)}/{n} feasible; {_pct(t)}"
    )
    if lifts:
        print(
            f"  lift {np.median(lifts):.3f} m; smallest rod-end clearance in the turn "
            f"(rod lengthened by the ±{settings.grasp.rod.offset_tolerance_m * 1000:.0f} mm grasp tolerance) "
            f"{min(clear) * 1000:.1f} mm"
        )
    for f in fails[:3]:
        print(f"  failed: {f}")


def _cube_planning(settings: Settings) -> None:
    spec = get_robot(settings.robot.model)
    T_ft = tool_geometry(settings).T_flange_tool()
    home = np.radians(settings.grasp.safe_home_joints_deg[spec.name])
    check = MotionCollisionCheck.from_settings(settings, _wall(settings))
    rng = np.random.default_rng(7)
    t, ok = [], 0
    colors = list(settings.grasp.cubes.drop_zones_m)
    n = 20
    for k in range(n):
        T = pose(
            rotation_z(rng.uniform(-np.pi, np.pi)), [rng.uniform(0.38, 0.58), rng.uniform(-0.2, 0.2), 0.025]
        )
        cube = CubeObservation.create(T, 0.05, colors[k % len(colors)])
        t0 = time.perf_counter()
        try:
            plan_pick_and_place(
                spec,
                cube,
                home,
                settings.grasp,
                T_ft,
                settings.gripper.stroke_m,
                q_home=home,
                collision_check=check,
            )
            ok += 1
        except Exception as exc:
            print(f"  cube failed: {type(exc).__name__}: {str(exc)[:120]}")
        t.append(time.perf_counter() - t0)
    print(f"cube pick-and-place planning ({n} cubes, 4 colours, wall obstacle): {ok}/{n} feasible; {_pct(t)}")


def run_twin_trials(seeds: list[int]) -> list[dict[str, float]]:
    from services.sim.twin import create_twin_engine
    from services.sim.twin import ground_truth as gt

    settings = load_settings(
        "sim",
        overrides={"logging": {"file": None}, "sim": {"twin": {"scene": {"cubes": [], "obstacle": False}}}},
    )
    spec = get_robot(settings.robot.model)
    T_ft = tool_geometry(settings).T_flange_tool()
    home = np.radians(settings.grasp.safe_home_joints_deg[spec.name])
    results = []
    for seed in seeds:
        engine = create_twin_engine(settings, seed=seed)
        rod = rod_from_twin(engine)
        t0 = time.perf_counter()
        plan = plan_pick_and_stand(
            spec, rod, engine.state().q, settings.grasp, T_ft, settings.gripper.stroke_m, q_home=home
        )
        plan_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        m = execute_plan_in_twin(engine, plan)
        stand = gt.evaluate_rod_standing(engine, "rod", settle_s=1.0)
        m.update(
            success=float(stand.success),
            tilt_after_deg=stand.tilt_deg,
            plan_s=plan_s,
            wall_s=time.perf_counter() - t0,
        )
        if not stand.success:
            m["reasons"] = "; ".join(stand.reasons)  # type: ignore[assignment]
        results.append(m)
    return results


def main() -> None:
    settings = load_settings("sim", overrides={"logging": {"file": None}})
    _force_closure_cost()
    _compute_grasps(settings)
    _rod_planning(settings)
    _cube_planning(settings)
    res = run_twin_trials(list(range(10)))
    ok = sum(r["success"] for r in res)
    print(
        f"rod plans executed in the twin (10 seeded scenes, perfect perception): {ok}/10 stand; "
        f"touch-down felt {sum(r['touch_detected'] for r in res):.0f}/10; "
        f"max slip {max(r['slip_mm'] for r in res):.1f} mm / {max(r['slip_deg'] for r in res):.1f}°; "
        f"tilt after release max {max(r['tilt_after_deg'] for r in res):.1f}°; "
        f"sim time p50 {np.median([r['sim_time_s'] for r in res]):.1f} s, wall p50 {np.median([r['wall_s'] for r in res]):.1f} s"
    )
    for r in res:
        if not r["success"]:
            print(f"  not standing: {r.get('reasons')}")


if __name__ == "__main__":
    main()
