"""Joint reference generators of the simulated controller (pure, sim time).

Each profile yields (q, qd, qdd) at time t since it started and knows its
duration. Velocity- and acceleration-limited, synchronised across joints the way
an industrial controller's PTP move is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class Profile:
    duration: float

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

    @property
    def end(self) -> np.ndarray:
        return self.sample(self.duration)[0]


def trapezoid_time(distance: float, vmax: float, amax: float) -> float:
    if distance <= 0:
        return 0.0
    if distance <= vmax * vmax / amax:  # triangular: never reaches vmax
        return 2.0 * np.sqrt(distance / amax)
    return distance / vmax + vmax / amax


@dataclass
class _Trapezoid:
    """Scalar normalised trapezoid s(t) in [0, 1] over a given duration with accel fraction."""

    duration: float
    t_acc: float

    def s(self, t: float) -> tuple[float, float, float]:
        T, ta = self.duration, self.t_acc
        if T <= 0:
            return 1.0, 0.0, 0.0
        t = min(max(t, 0.0), T)
        v = 1.0 / (T - ta)  # peak normalised speed
        a = v / ta if ta > 0 else 0.0
        if t < ta:
            return 0.5 * a * t * t, a * t, a
        if t <= T - ta:
            return 0.5 * a * ta * ta + v * (t - ta), v, 0.0
        tr = T - t
        return 1.0 - 0.5 * a * tr * tr, a * tr, -a


class PointToPoint(Profile):
    """Synchronised trapezoidal joint move (MovJ): every joint starts and stops together."""

    def __init__(self, q0: np.ndarray, q1: np.ndarray, vmax: np.ndarray, amax: np.ndarray):
        self.q0 = np.asarray(q0, dtype=float)
        self.delta = np.asarray(q1, dtype=float) - self.q0
        dist = np.abs(self.delta)
        vmax = np.asarray(vmax, dtype=float)
        amax = np.asarray(amax, dtype=float)
        T = max(trapezoid_time(d, v, a) for d, v, a in zip(dist, vmax, amax, strict=True))
        t_acc = T / 2
        # One shared normalised trapezoid: find the largest accel phase that keeps every joint
        # within its speed limit, and stretch T until every joint is within its accel limit too.
        for _ in range(200):
            if T <= 0:
                break
            t_acc = float(min(T / 2, np.min(T - dist / vmax)))
            if t_acc > 0 and np.all(dist / ((T - t_acc) * t_acc) <= amax * (1 + 1e-9)):
                break
            T *= 1.02
        self.duration = float(T)
        self._s = _Trapezoid(self.duration, max(t_acc, 0.0))

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s, sd, sdd = self._s.s(t)
        return self.q0 + s * self.delta, sd * self.delta, sdd * self.delta


class PathProfile(Profile):
    """A dense joint path (e.g. a straight TCP line solved by IK) timed by a trapezoid
    in path parameter, slowed so that no joint exceeds its limits."""

    def __init__(self, path: np.ndarray, duration_floor: float, vmax: np.ndarray, amax: np.ndarray):
        self.path = np.asarray(path, dtype=float)
        n = len(self.path)
        self._u = np.linspace(0.0, 1.0, n)
        # joint-space derivative magnitude along the normalised path
        dq_du = np.abs(np.diff(self.path, axis=0)) * (n - 1) if n > 1 else np.zeros((1, self.path.shape[1]))
        peak = dq_du.max(axis=0) if dq_du.size else np.zeros(self.path.shape[1])
        # with a trapezoid of accel fraction 1/4: peak ds/dt = 4/(3T)... use conservative bound 2/T
        with np.errstate(divide="ignore", invalid="ignore"):
            t_vel = np.nanmax(np.where(peak > 0, 2.0 * peak / vmax, 0.0)) if peak.size else 0.0
            t_acc = np.nanmax(np.where(peak > 0, np.sqrt(8.0 * peak / amax), 0.0)) if peak.size else 0.0
        self.duration = float(max(duration_floor, t_vel, t_acc, 1e-3))
        self._s = _Trapezoid(self.duration, self.duration / 4)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s, sd, sdd = self._s.s(t)
        n = len(self.path)
        if n == 1:
            return self.path[0].copy(), np.zeros(self.path.shape[1]), np.zeros(self.path.shape[1])
        x = s * (n - 1)
        i = min(int(x), n - 2)
        f = x - i
        q = self.path[i] * (1 - f) + self.path[i + 1] * f
        dq_ds = (self.path[i + 1] - self.path[i]) * (n - 1)
        return q, dq_ds * sd, dq_ds * sdd


class LinearInTime(Profile):
    """ServoJ: reach the target in exactly t seconds at constant velocity."""

    def __init__(self, q0: np.ndarray, q1: np.ndarray, duration: float):
        self.q0 = np.asarray(q0, dtype=float)
        self.delta = np.asarray(q1, dtype=float) - self.q0
        self.duration = float(max(duration, 1e-6))

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f = min(max(t / self.duration, 0.0), 1.0)
        qd = self.delta / self.duration if t < self.duration else np.zeros_like(self.delta)
        return self.q0 + f * self.delta, qd, np.zeros_like(self.delta)


class Dwell(Profile):
    """Hold still for a duration (used for the gripper's DO actuation delay)."""

    def __init__(self, q: np.ndarray, duration: float):
        self.q = np.asarray(q, dtype=float)
        self.duration = float(duration)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        z = np.zeros_like(self.q)
        return self.q.copy(), z, z
