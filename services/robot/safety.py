"""Checks every command must pass before it leaves the driver (pure).

Joint position limits, per-joint velocity limits of what is streamed, and the
tool tip inside the configured workspace box. A violation raises
LimitViolationError naming the joint / sample / coordinate — nothing is sent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.common.errors import InvalidInputError, LimitViolationError
from services.common.settings import WorkspaceBounds
from services.kinematics import analytic
from services.kinematics.robot_models import RobotSpec

# the streamed samples of a trajectory timed at exactly its limits may read a hair above them (the
# servo period cuts a jerk-limited profile); 5 % is far below what an unplanned speed step produces
ACCELERATION_MARGIN = 1.05
WIRE_DECIMALS_DEG = 6  # the command codec's precision (services.dobot.fmt_float)


@dataclass(frozen=True)
class SafetyLimits:
    spec: RobotSpec
    workspace: WorkspaceBounds
    velocity_scale: float = 1.0  # fraction of the model's joint speed limits allowed
    T_flange_tool: np.ndarray | None = None

    def check_joints(self, q: np.ndarray, what: str = "joint target") -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape[-1] != self.spec.dof:
            raise InvalidInputError(f"{what} needs {self.spec.dof} joint values, got {q.shape[-1]}")
        if not np.all(np.isfinite(q)):
            raise InvalidInputError(f"{what} contains NaN or infinite values")
        qs = q.reshape(-1, self.spec.dof)
        # as the controller will read it: degrees with 6 decimals on the wire (a target at the limit
        # must not round to beyond it)
        qs = np.deg2rad(np.round(np.rad2deg(qs), WIRE_DECIMALS_DEG))
        bad = (qs < self.spec.lower - 1e-12) | (qs > self.spec.upper + 1e-12)
        if bad.any():
            k, j = (int(x[0]) for x in np.nonzero(bad))
            raise LimitViolationError(
                f"{what}{f' sample {k}' if qs.shape[0] > 1 else ''}: joint {j + 1} = "
                f"{np.rad2deg(qs[k, j]):.3f}° is outside [{np.rad2deg(self.spec.lower[j]):.1f}°, "
                f"{np.rad2deg(self.spec.upper[j]):.1f}°]; not sent"
            )
        return q

    def tool_positions(self, q: np.ndarray) -> np.ndarray:
        """The tool tip (base frame, (N, 3) m) at each joint vector of ``q``."""
        qs = np.asarray(q, dtype=float).reshape(-1, self.spec.dof)
        return analytic.fk(self.spec, qs, self.T_flange_tool)[:, :3, 3]

    def check_workspace(self, q: np.ndarray, what: str = "joint target") -> None:
        p = self.tool_positions(q)
        lo, hi = np.array(self.workspace.min), np.array(self.workspace.max)
        bad = (p < lo) | (p > hi)
        if bad.any():
            k, axis = (int(x[0]) for x in np.nonzero(bad))
            raise LimitViolationError(
                f"{what}{f' sample {k}' if p.shape[0] > 1 else ''}: tool tip at "
                f"({p[k, 0]:.3f}, {p[k, 1]:.3f}, {p[k, 2]:.3f}) m leaves the workspace on "
                f"{'xyz'[axis]} (bounds {lo[axis]:.3f}..{hi[axis]:.3f} m); not sent"
            )

    def check_velocities(self, q_samples: np.ndarray, dt: float, q_start: np.ndarray | None = None) -> None:
        """Joint speeds implied by consecutive streamed samples (and the start) stay within limits."""
        qs = np.asarray(q_samples, dtype=float).reshape(-1, self.spec.dof)
        if q_start is not None:
            qs = np.vstack([np.asarray(q_start, dtype=float)[None], qs])
        if qs.shape[0] < 2:
            return
        speed = np.abs(np.diff(qs, axis=0)) / dt
        vmax = self.spec.max_velocity * self.velocity_scale
        bad = speed > vmax * (1 + 1e-6)
        if bad.any():
            k, j = (int(x[0]) for x in np.nonzero(bad))
            raise LimitViolationError(
                f"trajectory step {k}: joint {j + 1} would move at {np.rad2deg(speed[k, j]):.1f}°/s, "
                f"above its limit {np.rad2deg(vmax[j]):.1f}°/s; not sent"
            )

    def check_accelerations(self, q_samples: np.ndarray, dt: float, q_before: np.ndarray) -> None:
        """Joint accelerations implied by the streamed samples stay within the model's limits.

        ``q_before``: the two positions the stream continues from, oldest first (the same one twice when
        the arm starts at rest), so the first samples are judged against the motion they continue. The
        second difference of positions sampled every ``dt`` is a weighted mean of the acceleration over
        two periods, so a trajectory within its limits passes; a step in speed does not."""
        before = np.asarray(q_before, dtype=float).reshape(2, self.spec.dof)
        qs = np.vstack([before, np.asarray(q_samples, dtype=float).reshape(-1, self.spec.dof)])
        acc = np.abs(np.diff(qs, n=2, axis=0)) / dt**2
        amax = self.spec.max_acceleration * ACCELERATION_MARGIN
        bad = acc > amax
        if bad.any():
            k, j = (int(x[0]) for x in np.nonzero(bad))
            raise LimitViolationError(
                f"trajectory step {k}: joint {j + 1} would accelerate at {np.rad2deg(acc[k, j]):.0f}°/s², "
                f"above its limit {np.rad2deg(self.spec.max_acceleration[j]):.0f}°/s²; not sent"
            )

    def check_all(self, q: np.ndarray, what: str = "joint target") -> np.ndarray:
        q = self.check_joints(q, what)
        self.check_workspace(q, what)
        return q


def speed_ratio_field(value: float, name: str = "speed_ratio") -> int | None:
    """A requested speed ratio (1-100 %; 0 = the configured default) as the controller's integer ratio."""
    if not math.isfinite(value):
        raise InvalidInputError(f"{name} must be a finite percentage, got {value}")
    if value == 0:
        return None
    if not 1 <= value <= 100:
        raise InvalidInputError(f"{name} must be 1-100 %, got {value:g}")
    return round(value)


def cap_ratio(cap: float, limits: np.ndarray, name: str, unit: str) -> int | None:
    """The controller ratio (1-100 %) that keeps every joint at or under ``cap`` (``unit``); None for 0.

    A ratio scales each joint's own limit, so the fastest joint decides. A cap below 1 % of it cannot be
    honoured and is refused, never ignored."""
    if not math.isfinite(cap) or cap < 0:
        raise InvalidInputError(f"{name} must be a finite value >= 0 {unit}, got {cap}")
    if cap == 0:
        return None
    fastest = float(np.max(limits))
    ratio = math.floor(100.0 * cap / fastest + 1e-9)
    if ratio < 1:
        raise InvalidInputError(
            f"{name} {cap:g} {unit} is below the slowest the controller moves (1 % = {fastest / 100:.4g} {unit})"
        )
    return min(ratio, 100)
