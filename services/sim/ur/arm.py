"""The simulated UR arm's motion core (pure, controller time): what URScript's movej, movel, servoj,
speedj, stopj/stopl do to the joint reference, and the safety system's protective stop.

The reference is tracked by a :class:`services.sim.engine.MotionEngine` (kinematic here; the MuJoCo
twin can stand in). Limits are the robot model's (``services.kinematics.robot_models``): a target
beyond a joint limit, or a request faster than the joint speed limit, ends in a protective stop
before the arm moves, as the safety system of a real controller stops it (docs/ur/rtde.md).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from services.common.errors import IKFailureError
from services.kinematics import analytic
from services.kinematics.cartesian import interpolate_poses
from services.kinematics.robot_models import RobotSpec
from services.sim.motion_profiles import (
    LinearInTime,
    PathProfile,
    PointToPoint,
    Profile,
    trapezoid_time,
)

SPEED_TOLERANCE = 1.05  # a request this much over the joint speed limit is a violation, not rounding
LINE_STEP_M = 0.002  # moveL: IK every 2 mm along the line
LINE_STEP_RAD = np.deg2rad(0.5)


class MotionKind(enum.Enum):
    IDLE = "idle"
    MOVEJ = "movej"
    MOVEL = "movel"
    SERVOJ = "servoj"
    SPEEDJ = "speedj"
    STOP = "stop"


class SafetyViolation(Exception):
    """A request the safety system answers with a protective stop (the message says why)."""


class MotionFailure(Exception):
    """A request the program cannot execute (an unreachable pose): the program stops."""


@dataclass
class Reference:
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


class ArmMotion:
    """The joint reference of one arm and the motion producing it."""

    def __init__(self, spec: RobotSpec, q0: np.ndarray):
        self.spec = spec
        z = np.zeros(spec.dof)
        self.ref = Reference(np.asarray(q0, dtype=float).copy(), z.copy(), z.copy())
        self.kind = MotionKind.IDLE
        self._profile: Profile | None = None
        self._t = 0.0
        self._servo_target: np.ndarray | None = None
        self._servo_next: tuple[np.ndarray, float] | None = None  # given while a servoj's t still runs
        self._speed_target = z.copy()
        self._accel = 1.0
        self.T_flange_tcp = np.eye(4)

    # ------------------------------------------------------------ checks
    def check_joints(self, q: np.ndarray, what: str) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.spec.dof,) or not np.all(np.isfinite(q)):
            raise SafetyViolation(f"{what}: target is not {self.spec.dof} finite joint values")
        bad = np.flatnonzero((q < self.spec.lower - 1e-9) | (q > self.spec.upper + 1e-9))
        if bad.size:
            j = int(bad[0])
            raise SafetyViolation(
                f"{what}: joint {j} ({self.spec.joint_names[j]}) target {q[j]:.4f} rad is beyond its "
                f"limit [{self.spec.lower[j]:.4f}, {self.spec.upper[j]:.4f}] rad (joint position limit)"
            )
        return q

    def _check_speed(self, v: np.ndarray, what: str) -> None:
        over = np.flatnonzero(np.abs(v) > self.spec.max_velocity * SPEED_TOLERANCE)
        if over.size:
            j = int(over[0])
            raise SafetyViolation(
                f"{what}: joint {j} ({self.spec.joint_names[j]}) speed {abs(v[j]):.3f} rad/s exceeds its limit "
                f"{self.spec.max_velocity[j]:.3f} rad/s (joint speed limit)"
            )

    @property
    def moving(self) -> bool:
        return self.kind is not MotionKind.IDLE

    # ------------------------------------------------------------ commands
    def movej(self, q: np.ndarray, v: float, a: float) -> None:
        q = self.check_joints(q, "movej")
        self._check_speed(np.full(self.spec.dof, v), "movej")
        vmax = np.full(self.spec.dof, max(v, 1e-4))
        amax = np.full(self.spec.dof, max(a, 1e-4))
        self._start(MotionKind.MOVEJ, PointToPoint(self.ref.q, q, vmax, amax))

    def movel(self, T_base_tcp_goal: np.ndarray, v: float, a: float) -> None:
        """A straight TCP line (position lerp, orientation slerp) at tool speed ``v``."""
        T_start = analytic.fk(self.spec, self.ref.q, self.T_flange_tcp)
        poses = interpolate_poses(T_start, T_base_tcp_goal, LINE_STEP_M, LINE_STEP_RAD)
        inv = np.linalg.inv(self.T_flange_tcp)
        path = [self.ref.q.copy()]
        try:
            for T in poses[1:]:
                path.append(analytic.solve_nearest(self.spec, T @ inv, path[-1]))
        except IKFailureError as exc:
            raise MotionFailure(f"movel: inverse kinematics failed along the line: {exc}") from exc
        joints = np.array(path)
        jumps = np.max(np.abs(np.diff(joints, axis=0)), axis=1) if len(joints) > 1 else np.zeros(1)
        if float(np.max(jumps)) > 0.2:  # a branch flip between two 2 mm steps: a singularity
            raise MotionFailure("movel: the line passes through a singularity (joint jump on the path)")
        self.check_joints(joints[-1], "movel")
        dist = float(np.linalg.norm(T_base_tcp_goal[:3, 3] - T_start[:3, 3]))
        duration = trapezoid_time(dist, max(v, 1e-4), max(a, 1e-4))
        self._start(
            MotionKind.MOVEL,
            PathProfile(joints, duration, self.spec.max_velocity, self.spec.max_acceleration),
        )

    def servoj(self, q: np.ndarray, t: float) -> None:
        """Track ``q``, reached ``t`` seconds after the servoj running now has had its ``t``: URScript's
        servoj blocks for ``t``, so the script's servo thread takes up a target given meanwhile once the
        running one's time is over (the newest then, as its one target variable holds)."""
        q = self.check_joints(q, "servoj")
        t = max(float(t), 0.002)
        same = self._servo_target is not None and np.array_equal(q, self._servo_target)
        if self.kind is MotionKind.SERVOJ and same:
            return  # the script's servo thread repeats the same target every cycle
        self._servo_target = q.copy()
        if self.kind is MotionKind.SERVOJ and self._profile is not None and self._t < self._profile.duration:
            self._servo_next = (q.copy(), t)
            return
        self._check_speed((q - self.ref.q) / t, "servoj")
        self._start(MotionKind.SERVOJ, LinearInTime(self.ref.q, q, t))

    def speedj(self, qd: np.ndarray, a: float) -> None:
        qd = np.asarray(qd, dtype=float)
        self._check_speed(qd, "speedj")
        self._speed_target = qd.copy()
        self._accel = max(a, 1e-4)
        self.kind, self._profile = MotionKind.SPEEDJ, None

    def stop(self, a: float) -> None:
        """stopj/stopl/servo stop: decelerate every joint at ``a`` rad/s² (joint space)."""
        if self.kind is MotionKind.IDLE:
            return
        self._accel = max(a, 1e-4)
        self.kind, self._profile, self._servo_next = MotionKind.STOP, None, None

    def halt(self) -> None:
        """Standstill at once (protective stop, e-stop, power off)."""
        self.kind, self._profile, self._servo_target = MotionKind.IDLE, None, None
        self._servo_next = None
        self.ref.qd[:] = 0.0
        self.ref.qdd[:] = 0.0

    def _start(self, kind: MotionKind, profile: Profile) -> None:
        self.kind, self._profile, self._t = kind, profile, 0.0
        self._servo_next = None

    # ------------------------------------------------------------ time
    def step(self, dt: float) -> None:
        """Advance the reference by ``dt``; SafetyViolation when it would leave the joint limits."""
        if self.kind in (MotionKind.MOVEJ, MotionKind.MOVEL, MotionKind.SERVOJ):
            assert self._profile is not None
            self._t += dt
            q, qd, qdd = self._profile.sample(self._t)
            self.ref = Reference(q, qd, qdd)
            if self._t >= self._profile.duration:
                self.ref.qd[:] = 0.0
                self.ref.qdd[:] = 0.0
                if self.kind is not MotionKind.SERVOJ:  # servoj holds its last target until stopped
                    self.kind, self._profile = MotionKind.IDLE, None
                elif self._servo_next is not None:  # the servo thread's next servoj, on schedule
                    q_next, t_next = self._servo_next
                    carry = self._t - self._profile.duration
                    self._check_speed((q_next - self.ref.q) / t_next, "servoj")
                    self._start(MotionKind.SERVOJ, LinearInTime(self.ref.q, q_next, t_next))
                    self._t = carry
        elif self.kind is MotionKind.SPEEDJ:
            dv = self._speed_target - self.ref.qd
            lim = self._accel * dt
            step = dv * min(1.0, lim / max(float(np.max(np.abs(dv))), 1e-12))
            self._integrate(self.ref.qd + step, dt)
        elif self.kind is MotionKind.STOP:
            peak = float(np.max(np.abs(self.ref.qd)))
            if peak <= self._accel * dt:
                self.halt()
            else:
                self._integrate(self.ref.qd * (1.0 - self._accel * dt / peak), dt)

    def _integrate(self, qd_new: np.ndarray, dt: float) -> None:
        q_new = self.ref.q + 0.5 * (self.ref.qd + qd_new) * dt
        self.check_joints(q_new, self.kind.value)
        self.ref = Reference(q_new, qd_new, (qd_new - self.ref.qd) / dt)
