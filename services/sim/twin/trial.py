"""A scripted pick-and-stand trial on the twin (evaluation, tests and benchmarks only).

It drives :class:`TwinEngine` directly — not through the Dobot protocol — along straight tool
paths solved with the analytic IK at every 8 ms tick (dense Cartesian IK, one IK branch for the
whole path), closes the gripper through the digital outputs, detects touch-down from the wrist
force reading (not from ground truth), and scores the result with :mod:`ground_truth`. The real
pipeline (vision → grasp → motion → driver) replaces this script; the twin and checks stay.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from services.common.errors import CollisionDetectedError, IKFailureError
from services.common.frames import invert_transform, make_transform
from services.kinematics.analytic import fk, fk_all, ik_all, nearest_equivalent, solutions_within_limits
from services.kinematics.robot_models import RobotSpec
from services.sim.engine import EngineState
from services.sim.twin import ground_truth as gt
from services.sim.twin.engine import TOOL_DO_SHIFT, TwinEngine

Array = np.ndarray

TICK_S = 0.008
MAX_JOINT_STEP_RAD = 0.08  # per tick on a Cartesian path; larger means an IK branch jump
TOUCH_FORCE_DROP_N = 0.6  # the notes: touch-down = the held weight (0.98 N) seen > 0.6 N less


def _quintic(s: float) -> tuple[float, float, float]:
    """Position, velocity and acceleration of 10s³−15s⁴+6s⁵ (per unit time of s)."""
    return (
        10 * s**3 - 15 * s**4 + 6 * s**5,
        30 * s**2 - 60 * s**3 + 30 * s**4,
        60 * s - 180 * s**2 + 120 * s**3,
    )


def rotation_about(axis: Array, angle: float) -> Array:
    a = np.asarray(axis, dtype=float)
    return Rotation.from_rotvec(a / np.linalg.norm(a) * angle).as_matrix()


class ScriptedArm:
    """Moves the twin's arm through IK-solved tool paths, tick by tick, in sim time."""

    def __init__(self, engine: TwinEngine):
        self.engine = engine
        self.spec = engine.world.spec
        self.T_flange_tool = engine.world.T_flange_tool
        self.T_tool_flange = invert_transform(self.T_flange_tool)
        self.q = engine.state().q.copy()
        self.last: EngineState = engine.state()

    def _tick(self, q: Array, qd: Array, qdd: Array) -> EngineState:
        self.last = self.engine.step(TICK_S, q, qd, qdd)
        self.q = q
        if self.last.collision:  # the controller would raise alarm 117 and stop
            self.engine.hold()
            raise CollisionDetectedError(self.last.collision)
        return self.last

    def wait(self, duration_s: float) -> None:
        zeros = np.zeros_like(self.q)
        for _ in range(max(1, round(duration_s / TICK_S))):
            self._tick(self.q, zeros, zeros)

    def set_gripper(self, closed: bool, wait_s: float = 0.6) -> None:
        g = self.engine.world.gripper
        shift = TOOL_DO_SHIFT if g.tool_outputs else 0
        mask = 1 << (g.close_do - 1) if closed else (0 if g.open_do is None else 1 << (g.open_do - 1))
        mask <<= shift
        self.engine.set_digital_outputs(mask)
        self.wait(wait_s)

    def ik(self, T_base_tool: Array, seed: Array) -> Array:
        sols = solutions_within_limits(self.spec, T_base_tool @ self.T_tool_flange, seed)
        if sols.shape[0] == 0:
            p = T_base_tool[:3, 3]
            raise IKFailureError(f"no IK solution for the tool at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m")
        return sols[0]

    def path_branch(self, key_poses: list[Array]) -> Array:
        """Pick one IK branch for the whole path: every key pose reachable in it with the elbow and
        wrist well above the table; return its solution for the first pose (nearest the arm)."""
        T_flanges = np.stack([T @ self.T_tool_flange for T in key_poses])
        q_all, valid = ik_all(self.spec, T_flanges)  # (k, 8, 6): branch b is the same choice in every pose
        best: tuple[float, Array] | None = None
        for b in range(q_all.shape[1]):
            if not np.all(valid[:, b]):
                continue
            seed = self.q
            ok = True
            for k in range(len(key_poses)):
                q = nearest_equivalent(self.spec, q_all[k, b], seed)
                if not (self.spec.within_limits(q) and _clear_of_table(self.spec, q)):
                    ok = False
                    break
                seed = q
            if ok:
                q0 = nearest_equivalent(self.spec, q_all[0, b], self.q)
                cost = float(np.max(np.abs(q0 - self.q)))
                if best is None or cost < best[0]:
                    best = (cost, q0)
        if best is None:
            p = key_poses[0][:3, 3]
            raise IKFailureError(
                f"no IK branch keeps the arm clear of the table along the path from "
                f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"
            )
        return best[1]

    def move_joints(self, q_goal: Array, duration_s: float) -> None:
        q0 = self.q.copy()
        dq = np.asarray(q_goal, dtype=float) - q0
        n = max(1, round(duration_s / TICK_S))
        T = n * TICK_S
        for k in range(1, n + 1):
            p, v, a = _quintic(k / n)
            self._tick(q0 + dq * p, dq * v / T, dq * a / T**2)

    def move_linear(
        self, T_goal: Array, duration_s: float, stop: Callable[[EngineState], bool] | None = None
    ) -> bool:
        """Straight tool path (position lerp, orientation slerp); returns True if ``stop`` fired."""
        T0 = self.tool_pose()
        slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([T0[:3, :3], T_goal[:3, :3]])))
        n = max(1, round(duration_s / TICK_S))
        q_prev, qd_prev = self.q.copy(), np.zeros_like(self.q)
        for k in range(1, n + 1):
            s = _quintic(k / n)[0]
            T = make_transform(slerp([s]).as_matrix()[0], T0[:3, 3] + s * (T_goal[:3, 3] - T0[:3, 3]))
            q = self.ik(T, q_prev)
            if np.max(np.abs(q - q_prev)) > MAX_JOINT_STEP_RAD:
                raise IKFailureError(
                    f"IK branch jump of {np.degrees(np.max(np.abs(q - q_prev))):.0f}° on a path"
                )
            qd = (q - q_prev) / TICK_S
            state = self._tick(q, qd, (qd - qd_prev) / TICK_S)
            q_prev, qd_prev = q, qd
            if stop is not None and stop(state):
                self.hold()
                return True
        self.wait(0.05)
        return False

    def hold(self) -> None:
        self.q = self.last.q.copy()
        self.wait(0.05)

    def tool_pose(self) -> Array:
        """Tool pose of the current *reference* (what the controller believes; not ground truth)."""
        return fk(self.spec, self.q) @ self.T_flange_tool


def _clear_of_table(spec: RobotSpec, q: Array, min_z: float = 0.10) -> bool:
    """Elbow and wrist joints high enough that their links stay off the table."""
    z = fk_all(spec, q)[:, 2, 3]
    return bool(np.all(z[2:6] > min_z))


@dataclass
class RodTrialResult:
    success: bool
    stand: gt.RodStandResult | None
    metrics: gt.GraspMetrics
    sim_time_s: float
    error: str | None = None
    phases: dict[str, float] = field(default_factory=dict)


def rod_stand_poses(T_base_rod: Array, lift_m: float, outward: bool = True) -> dict[str, Array]:
    """Tool poses of the pick-and-stand for a rod lying on the table (top-down grasp at its centre).

    The jaws close across the rod (tool y ⟂ rod); the 90° turn is about the jaw axis, so the tool
    ends pointing horizontally along the old rod axis, outward from the robot, and the rod stands.
    """
    c = T_base_rod[:3, 3]
    a = T_base_rod[:3, 2].copy()
    a[2] = 0.0
    a /= np.linalg.norm(a)
    if (a[:2] @ c[:2] < 0) == outward:  # outward: the wrist need not fold back toward the base
        a = -a
    z_t = np.array([0.0, 0.0, -1.0])
    y_t = np.cross(z_t, a)
    R_grasp = np.column_stack([a, y_t, z_t])
    grasp = make_transform(R_grasp, c + [0.0, 0.0, 0.001])
    R_turned = rotation_about(y_t, np.pi / 2) @ R_grasp
    lift = make_transform(R_grasp, grasp[:3, 3] + [0.0, 0.0, lift_m])
    return {
        "pre_grasp": make_transform(R_grasp, grasp[:3, 3] + [0.0, 0.0, 0.10]),
        "grasp": grasp,
        "lift": lift,
        "turned": make_transform(R_turned, lift[:3, 3]),
    }


def _retreat(T_base_tool: Array, distance_m: float) -> tuple[Array, Array]:
    """Back out along the approach axis until the fingertips clear the rod, then up."""
    back = T_base_tool.copy()
    back[:3, 3] -= distance_m * T_base_tool[:3, 2]
    up = back.copy()
    up[2, 3] += 0.10
    return back, up


def run_rod_stand_trial(
    engine: TwinEngine,
    name: str = "rod",
    lift_m: float = 0.15,
    place_clearance_m: float = 0.03,
    retreat_m: float = 0.05,
) -> RodTrialResult:
    """Pick the rod, lift, turn it upright, lower until the wrist feels the touch, release, retreat."""
    arm = ScriptedArm(engine)
    metrics = gt.GraspMetrics()
    phases: dict[str, float] = {}
    obj = engine.scene.get(name)
    half_len = obj.size_m[2] / 2
    t_start = engine.time_s
    try:
        T_rod = gt.object_pose(engine, name)  # the "perfect perception" input
        arm.set_gripper(False, wait_s=0.2)
        last_error: IKFailureError | None = None
        for outward in (True, False):  # turn the rod so the tool ends pointing outward, else inward
            poses = rod_stand_poses(T_rod, lift_m, outward)
            T_low = poses["turned"].copy()
            T_low[2, 3] = half_len + place_clearance_m
            T_placed = poses["turned"].copy()
            T_placed[2, 3] = half_len
            back, up = _retreat(T_placed, retreat_m)
            try:
                q_start = arm.path_branch(
                    [poses["pre_grasp"], poses["grasp"], poses["lift"], poses["turned"], T_low, back, up]
                )
                break
            except IKFailureError as exc:
                last_error = exc
        else:
            assert last_error is not None
            raise last_error
        arm.move_joints(q_start, 2.0)
        phases["approach"] = engine.time_s - t_start
        arm.move_linear(poses["grasp"], 1.0)
        arm.set_gripper(True, wait_s=0.6)
        phases["grasp"] = engine.time_s - t_start
        T_ref = gt.T_tool_object(engine, name)

        def track_slip(_: EngineState) -> bool:
            mm, deg = gt.slip(T_ref, gt.T_tool_object(engine, name))
            metrics.slip_mm, metrics.slip_deg = max(metrics.slip_mm, mm), max(metrics.slip_deg, deg)
            return False

        arm.move_linear(poses["lift"], 1.5, stop=track_slip)
        arm.move_linear(poses["turned"], 2.0, stop=track_slip)
        phases["turned"] = engine.time_s - t_start
        # Lower: fast to a few cm above the expected touch, then slowly until the force changes.
        arm.move_linear(T_low, 1.0, stop=track_slip)
        arm.wait(0.2)
        track_slip(arm.last)
        fz_ref = arm.last.tcp_force[2]
        metrics.tilt_before_place_deg = gt.axis_tilt_deg(gt.object_pose(engine, name))
        T_touch = T_low.copy()
        T_touch[2, 3] = half_len - 0.01
        touched = arm.move_linear(
            T_touch,
            (place_clearance_m + 0.01) / 0.02,
            stop=lambda s: s.tcp_force[2] - fz_ref > TOUCH_FORCE_DROP_N,
        )
        metrics.extra["touch_detected"] = float(touched)
        phases["placed"] = engine.time_s - t_start
        arm.set_gripper(False, wait_s=0.5)
        T_back, T_up = _retreat(arm.tool_pose(), retreat_m)
        arm.move_linear(T_back, 1.0)
        arm.move_linear(T_up, 1.0)
        stand = gt.evaluate_rod_standing(engine, name, settle_s=1.0)
        metrics.tilt_after_release_deg = stand.tilt_deg
        return RodTrialResult(stand.success, stand, metrics, engine.time_s - t_start, phases=phases)
    except (IKFailureError, CollisionDetectedError) as exc:
        return RodTrialResult(False, None, metrics, engine.time_s - t_start, error=str(exc), phases=phases)
