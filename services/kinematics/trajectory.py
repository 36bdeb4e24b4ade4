"""Joint trajectories: the value types and the independent limit check.

A :class:`JointTrajectory` is a list of knots (time, position, velocity, acceleration).
Between knots it is the unique quintic that matches position, velocity and
acceleration at both ends, so :meth:`JointTrajectory.sample` is C2 at any ``t``
and a segment with zero velocity and acceleration at both ends is exactly the
minimum-jerk (quintic smoothstep) profile ``s = 10τ³ − 15τ⁴ + 6τ⁵``.
A timed trajectory's knots (10 ms apart) are what a driver streams: sampled every 30 ms it sends
knots, and faster it reads positions a few ms from them. So the acceleration that counts is the knots'
and that of their stream; the quintic is how positions between them are read. A trajectory whose
knots lie far apart (a paced touch-down: the path's points) is streamed off the quintic between them,
and is judged by its peaks (:meth:`JointTrajectory.acceleration_peaks`) where it is made.
:func:`verify_trajectory` checks a trajectory against :class:`JointLimits`
independently of whatever produced it (interpolation: ``services.kinematics.interpolation``;
time parameterisation: ``services.motion.timing``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from services.common.errors import InvalidInputError, TrajectoryLimitError
from services.kinematics.robot_models import RobotSpec

if TYPE_CHECKING:
    from pickplace.v1 import common_pb2

Array = NDArray[np.float64]

TWO_PI = 2.0 * math.pi


# --- limits ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits in SI units (rad, rad/s, rad/s², rad/s³). ``max_jerk`` may be None."""

    lower: Array
    upper: Array
    max_velocity: Array
    max_acceleration: Array
    max_jerk: Array | None = None

    def __post_init__(self) -> None:
        n = np.asarray(self.lower).shape[0]
        for name in ("lower", "upper", "max_velocity", "max_acceleration", "max_jerk"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.asarray(value, dtype=float)
            if arr.shape != (n,) or not np.all(np.isfinite(arr)):
                raise InvalidInputError(f"joint limit {name} must be {n} finite values, got {value!r}")
            object.__setattr__(self, name, arr)
        if np.any(self.lower >= self.upper):
            raise InvalidInputError(f"joint lower limits {self.lower} must be below upper {self.upper}")
        for name in ("max_velocity", "max_acceleration", "max_jerk"):
            value = getattr(self, name)
            if value is not None and np.any(value <= 0):
                raise InvalidInputError(f"joint limit {name} must be positive, got {value}")

    @property
    def dof(self) -> int:
        return int(self.lower.shape[0])

    @classmethod
    def from_spec(
        cls, spec: RobotSpec, velocity_scale: float = 1.0, acceleration_scale: float = 1.0, jerk: bool = True
    ) -> JointLimits:
        """The model's limits, velocity/acceleration/jerk scaled by the given fractions (0, 1]."""
        for name, s in (("velocity_scale", velocity_scale), ("acceleration_scale", acceleration_scale)):
            if not (math.isfinite(s) and 0.0 < s <= 1.0):
                raise InvalidInputError(f"{name} must be within (0, 1], got {s}")
        return cls(
            lower=spec.lower.copy(),
            upper=spec.upper.copy(),
            max_velocity=spec.max_velocity * velocity_scale,
            max_acceleration=spec.max_acceleration * acceleration_scale,
            max_jerk=spec.max_jerk * acceleration_scale if jerk else None,
        )

    def continuous(self) -> NDArray[np.bool_]:
        """Joints whose range spans at least a full turn (shortest-angle wrapping may apply)."""
        return (self.upper - self.lower) >= TWO_PI - 1e-9

    def check_positions(self, q: ArrayLike, name: str = "joint positions", tol: float = 1e-9) -> Array:
        """Finite, right length, within limits; InvalidInputError naming the joint and value otherwise."""
        arr = joint_vector(q, self.dof, name)
        bad = np.flatnonzero((arr < self.lower - tol) | (arr > self.upper + tol))
        if bad.size:
            i = int(bad[0])
            raise InvalidInputError(
                f"{name}: joint {i + 1} = {arr[i]:.6f} rad ({math.degrees(arr[i]):.3f}°) is outside "
                f"[{self.lower[i]:.4f}, {self.upper[i]:.4f}] rad"
            )
        return arr


def joint_vector(q: ArrayLike, dof: int, name: str = "joint positions") -> Array:
    """A finite float vector of ``dof`` values, or InvalidInputError saying what is wrong."""
    try:
        arr = np.asarray(q, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be numeric, got {q!r}") from exc
    if arr.shape[0] != dof:
        raise InvalidInputError(f"{name} must have {dof} values, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{name} contains NaN or infinite values: {arr.tolist()}")
    return arr


def joint_path(waypoints: ArrayLike, dof: int, name: str = "waypoints") -> Array:
    """A finite (N, dof) array with N >= 1."""
    try:
        arr = np.asarray(waypoints, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be numeric") from exc
    if arr.ndim == 1:
        arr = arr.reshape(1, -1)
    if arr.ndim != 2 or arr.shape[1] != dof or arr.shape[0] < 1:
        raise InvalidInputError(f"{name} must have shape (N, {dof}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{name} contain NaN or infinite values")
    return arr


# --- the trajectory type --------------------------------------------------------------------------
STILL_SPEED = 1e-9  # rad/s: a joint slower than this at a trajectory's end is at rest there


@dataclass
class JointTrajectory:
    """Time-parameterised joint trajectory; knots at ``times`` (s, increasing, first = 0)."""

    joint_names: tuple[str, ...]
    times: Array
    positions: Array
    velocities: Array
    accelerations: Array
    meta: dict[str, object] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        self.joint_names = tuple(self.joint_names)
        self.times = np.asarray(self.times, dtype=float).reshape(-1)
        n, dof = self.times.shape[0], len(self.joint_names)
        for name in ("positions", "velocities", "accelerations"):
            arr = np.asarray(getattr(self, name), dtype=float)
            if arr.shape != (n, dof):
                raise InvalidInputError(f"trajectory {name} must have shape ({n}, {dof}), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise InvalidInputError(f"trajectory {name} contain NaN or infinite values")
            setattr(self, name, arr)
        if n < 1:
            raise InvalidInputError("a trajectory needs at least one point")
        if not np.all(np.isfinite(self.times)):
            raise InvalidInputError("trajectory times contain NaN or infinite values")
        if abs(self.times[0]) > 1e-12:
            raise InvalidInputError(f"trajectory must start at t = 0, got {self.times[0]}")
        if n > 1 and np.any(np.diff(self.times) <= 0):
            k = int(np.flatnonzero(np.diff(self.times) <= 0)[0])
            raise InvalidInputError(
                f"trajectory times must increase strictly; t[{k}] = {self.times[k]} >= t[{k + 1}] = "
                f"{self.times[k + 1]}"
            )

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def starts_in_motion(self) -> bool:
        """It starts moving: it continues another trajectory, not a rest."""
        return bool(np.any(np.abs(self.velocities[0]) > STILL_SPEED))

    @property
    def ends_in_motion(self) -> bool:
        """It ends moving: another trajectory continues it."""
        return bool(np.any(np.abs(self.velocities[-1]) > STILL_SPEED))

    def __len__(self) -> int:
        return int(self.times.shape[0])

    @cached_property
    def _coefficients(self) -> Array:
        """Quintic coefficients per segment and joint: (N-1, 6, dof), in powers of τ = t - t_k."""
        h = np.diff(self.times)[:, None]
        p0, p1 = self.positions[:-1], self.positions[1:]
        v0, v1 = self.velocities[:-1], self.velocities[1:]
        a0, a1 = self.accelerations[:-1], self.accelerations[1:]
        d = p1 - p0
        c3 = (20 * d - (8 * v1 + 12 * v0) * h - (3 * a0 - a1) * h**2) / (2 * h**3)
        c4 = (-30 * d + (14 * v1 + 16 * v0) * h + (3 * a0 - 2 * a1) * h**2) / (2 * h**4)
        c5 = (12 * d - 6 * (v1 + v0) * h + (a1 - a0) * h**2) / (2 * h**5)
        return np.stack([p0, v0, a0 / 2, c3, c4, c5], axis=1)

    def streamed_accelerations(self) -> Array:
        """The acceleration the knots imply as a stream of positions, as a controller fed them sees it:
        each inner knot's second difference of positions over the intervals beside it ((N-2, dof)).
        It is a weighted mean of the motion's acceleration over those intervals, and the second
        difference over a multiple of the knot period a weighted mean of these."""
        if len(self) < 3:
            return np.zeros((0, self.dof))
        h = np.diff(self.times)[:, None]
        v = np.diff(self.positions, axis=0) / h
        return np.asarray(np.diff(v, axis=0) / (0.5 * (h[:-1] + h[1:])))

    def acceleration_peaks(self) -> tuple[Array, Array]:
        """The largest |acceleration| inside each knot interval, exactly, and when: ((N-1, dof), (N-1, dof)).

        Acceleration on a quintic segment is a cubic in τ; its extremes inside the interval are
        where the jerk (a quadratic) is zero. Sampling alone can miss them by a few 0.1 % where a
        bang-bang profile switches between knots.
        """
        h = np.diff(self.times)[:, None]
        c = self._coefficients
        c2, c3, c4, c5 = c[:, 2], c[:, 3], c[:, 4], c[:, 5]
        # jerk(τ) = 6 c3 + 24 c4 τ + 60 c5 τ²: roots of A τ² + B τ + C
        A, B, C = 60 * c5, 24 * c4, 6 * c3
        best = np.zeros_like(c2)
        at = np.zeros_like(c2)
        disc = B * B - 4 * A * C
        with np.errstate(divide="ignore", invalid="ignore"):
            root = np.sqrt(np.maximum(disc, 0.0))
            quadratic = np.abs(A) > 1e-12
            candidates = (
                np.where(quadratic, (-B + root) / (2 * A), np.where(np.abs(B) > 1e-12, -C / B, -1.0)),
                np.where(quadratic, (-B - root) / (2 * A), -1.0),
            )
        for tau in candidates:
            valid = (disc >= 0) & np.isfinite(tau) & (tau > 0) & (tau < h)
            tau = np.where(valid, tau, 0.0)
            acc = np.abs(2 * c2 + tau * (6 * c3 + tau * (12 * c4 + tau * 20 * c5)))
            better = valid & (acc > best)
            best = np.where(better, acc, best)
            at = np.where(better, tau, at)
        return best, self.times[:-1, None] + at

    def sample(self, t: float | ArrayLike, derivatives: int = 2) -> tuple[Array, ...]:
        """(q, qd, qdd[, qddd]) at time(s) ``t``; t is clamped to [0, duration].

        A scalar t gives vectors (dof,), an array of m times gives (m, dof) arrays.
        """
        if derivatives not in (0, 1, 2, 3):
            raise InvalidInputError(f"derivatives must be 0..3, got {derivatives}")
        scalar = np.ndim(t) == 0
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        if not np.all(np.isfinite(ts)):
            raise InvalidInputError(f"sample time must be finite, got {t!r}")
        ts = np.clip(ts, 0.0, self.duration)
        if len(self) == 1:
            out = [np.broadcast_to(self.positions[0], (ts.size, self.dof)).copy()]
            out += [np.zeros((ts.size, self.dof)) for _ in range(derivatives)]
        else:
            k = np.clip(np.searchsorted(self.times, ts, side="right") - 1, 0, len(self) - 2)
            tau = (ts - self.times[k])[:, None]
            c = self._coefficients[k]  # (m, 6, dof)
            out = [
                c[:, 0]
                + tau * (c[:, 1] + tau * (c[:, 2] + tau * (c[:, 3] + tau * (c[:, 4] + tau * c[:, 5]))))
            ]
            if derivatives >= 1:
                out.append(
                    c[:, 1]
                    + tau * (2 * c[:, 2] + tau * (3 * c[:, 3] + tau * (4 * c[:, 4] + tau * 5 * c[:, 5])))
                )
            if derivatives >= 2:
                out.append(2 * c[:, 2] + tau * (6 * c[:, 3] + tau * (12 * c[:, 4] + tau * 20 * c[:, 5])))
            if derivatives >= 3:
                out.append(6 * c[:, 3] + tau * (24 * c[:, 4] + tau * 60 * c[:, 5]))
        if scalar:
            return tuple(o[0] for o in out)
        return tuple(out)

    def resample(self, dt: float) -> JointTrajectory:
        """The same motion with knots every ``dt`` seconds (the last knot at the exact end)."""
        if not (math.isfinite(dt) and dt > 0):
            raise InvalidInputError(f"resample period must be positive, got {dt}")
        n = max(1, math.ceil(self.duration / dt - 1e-9))
        ts = np.minimum(np.arange(n + 1) * dt, self.duration) if self.duration > 0 else np.zeros(1)
        ts = np.unique(ts)
        q, qd, qdd = self.sample(ts)
        return JointTrajectory(self.joint_names, ts, q, qd, qdd, dict(self.meta))

    def window(self, t0: float, t1: float) -> JointTrajectory:
        """The part between ``t0`` and ``t1``, restarting at t = 0 (knots kept, ends sampled); a window
        to the end ends exactly as this one does."""
        if not (0.0 <= t0 < t1 <= self.duration + 1e-12):
            raise InvalidInputError(
                f"window [{t0}, {t1}] s is not within the trajectory's [0, {self.duration}] s"
            )
        inner = self.times[(self.times > t0 + 1e-9) & (self.times < t1 - 1e-9)]
        ts = np.concatenate([[t0], inner, [t1]])
        q, qd, qdd = self.sample(ts)
        if t1 >= self.duration:
            q[-1], qd[-1], qdd[-1] = self.positions[-1], self.velocities[-1], self.accelerations[-1]
        return JointTrajectory(self.joint_names, ts - t0, q, qd, qdd, dict(self.meta))

    def scaled(self, factor: float) -> JointTrajectory:
        """Slowed down uniformly by ``factor`` ≥ 1 (velocity /k, acceleration /k², jerk /k³)."""
        if not (math.isfinite(factor) and factor > 0):
            raise InvalidInputError(f"time scale factor must be positive, got {factor}")
        return JointTrajectory(
            self.joint_names,
            self.times * factor,
            self.positions,
            self.velocities / factor,
            self.accelerations / factor**2,
            dict(self.meta),
        )

    def append(self, other: JointTrajectory) -> JointTrajectory:
        """This trajectory followed by ``other`` (which must start where this one ends)."""
        if other.joint_names != self.joint_names:
            raise InvalidInputError(
                f"cannot join trajectories over {self.joint_names} and {other.joint_names}"
            )
        gap = np.max(np.abs(other.positions[0] - self.positions[-1]))
        if gap > 1e-6:
            raise InvalidInputError(f"trajectories do not meet: joint gap {gap:.3g} rad at the junction")
        return JointTrajectory(
            self.joint_names,
            np.concatenate([self.times, self.duration + other.times[1:]]),
            np.vstack([self.positions, other.positions[1:]]),
            np.vstack([self.velocities, other.velocities[1:]]),
            np.vstack([self.accelerations, other.accelerations[1:]]),
            dict(self.meta),
        )

    # --- protobuf (pickplace.v1.JointTrajectory) ---------------------------------------------
    def to_proto(self) -> common_pb2.JointTrajectory:
        from pickplace.v1 import common_pb2

        msg = common_pb2.JointTrajectory(joint_names=list(self.joint_names))
        for k in range(len(self)):
            msg.points.append(
                common_pb2.JointTrajectoryPoint(
                    positions=self.positions[k].tolist(),
                    velocities=self.velocities[k].tolist(),
                    accelerations=self.accelerations[k].tolist(),
                    time_from_start_s=float(self.times[k]),
                )
            )
        return msg

    @classmethod
    def from_proto(cls, msg: object) -> JointTrajectory:
        """Inverse of :meth:`to_proto`; missing velocities/accelerations are read as zero."""
        names = tuple(msg.joint_names)  # type: ignore[attr-defined]
        points = list(msg.points)  # type: ignore[attr-defined]
        if not names:
            raise InvalidInputError("trajectory message has no joint names")
        if not points:
            raise InvalidInputError("trajectory message has no points")
        dof = len(names)
        rows: dict[str, list[list[float]]] = {"positions": [], "velocities": [], "accelerations": []}
        for k, p in enumerate(points):
            for key in rows:
                values = list(getattr(p, key))
                if key != "positions" and not values:
                    values = [0.0] * dof
                if len(values) != dof:
                    raise InvalidInputError(f"trajectory point {k} has {len(values)} {key}, expected {dof}")
                rows[key].append(values)
        times = np.array([p.time_from_start_s for p in points], dtype=float)
        return cls(
            names,
            times,
            np.array(rows["positions"]),
            np.array(rows["velocities"]),
            np.array(rows["accelerations"]),
        )

    @classmethod
    def hold(cls, joint_names: Sequence[str], q: ArrayLike) -> JointTrajectory:
        """A single-point trajectory that stays at ``q``."""
        qv = joint_vector(q, len(joint_names))
        z = np.zeros((1, qv.size))
        return cls(tuple(joint_names), np.zeros(1), qv[None], z, z.copy())


# --- verification ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class LimitReport:
    """Worst values over the verification samples, as fractions of each limit (1.0 = at the limit)."""

    position_excess_rad: float
    velocity_ratio: float
    acceleration_ratio: float
    jerk_ratio: float
    samples: int


def verify_trajectory(
    traj: JointTrajectory,
    limits: JointLimits,
    *,
    start: ArrayLike | None = None,
    goal: ArrayLike | None = None,
    samples_per_segment: int = 24,
    tolerance: float = 1e-3,
    position_tol: float = 1e-6,
    at_rest: bool = True,
) -> LimitReport:
    """Independent check of the sampled trajectory; TrajectoryLimitError naming the first violation.

    Positions and velocities: every knot interval sampled at ``samples_per_segment`` points, with
    the same interpolation the executor uses (:meth:`JointTrajectory.sample`). Acceleration: at the
    knots, and as the second differences of the knots' positions
    (:meth:`JointTrajectory.streamed_accelerations`), the acceleration a controller streamed them is
    asked for (module docstring). Velocity and acceleration may exceed their limits by the relative
    ``tolerance`` at most. Jerk (when the limits carry it) is checked as the mean jerk over each knot
    interval, i.e. the change of commanded acceleration between knots. Also checks that the trajectory
    starts and ends at rest (with ``at_rest``), at ``start`` / ``goal`` when given.
    """
    if traj.dof != limits.dof:
        raise InvalidInputError(f"trajectory has {traj.dof} joints, limits have {limits.dof}")
    if samples_per_segment < 2:
        raise InvalidInputError(f"samples_per_segment must be >= 2, got {samples_per_segment}")
    if len(traj) > 1:
        frac = np.linspace(0.0, 1.0, samples_per_segment + 1)[:-1]
        ts = (traj.times[:-1, None] + np.diff(traj.times)[:, None] * frac[None, :]).ravel()
        ts = np.append(ts, traj.duration)
    else:
        ts = traj.times.copy()
    q, qd = traj.sample(ts, derivatives=1)
    below = limits.lower - q
    above = q - limits.upper
    excess = np.maximum(below, above)
    worst = float(np.max(excess))
    if worst > position_tol:
        k, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
        raise TrajectoryLimitError(
            f"joint {j + 1} position {q[k, j]:.6f} rad at t = {ts[k]:.4f} s is outside "
            f"[{limits.lower[j]:.4f}, {limits.upper[j]:.4f}]"
        )
    sample_t = np.broadcast_to(ts[:, None], qd.shape)
    # acceleration at the knots and as their stream (module docstring), not along the quintic between
    # them: where the timed profile switches its acceleration inside a knot interval the quintic
    # overshoots both knots' values (by a third of the step at a full switch), a bend no streamed
    # position shows (the driver judges the second differences of what it streams, as here)
    knot_t = np.broadcast_to(traj.times[:, None], traj.accelerations.shape)
    acc = np.vstack([traj.accelerations, traj.streamed_accelerations()])
    acc_t = np.vstack([knot_t, knot_t[1:-1]])
    v_ratio = np.abs(qd) / limits.max_velocity
    a_ratio = np.abs(acc) / limits.max_acceleration
    for label, ratio, values, times, unit in (
        ("velocity", v_ratio, qd, sample_t, "rad/s"),
        ("acceleration", a_ratio, acc, acc_t, "rad/s²"),
    ):
        if float(np.max(ratio)) > 1.0 + tolerance:
            k, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
            lim = limits.max_velocity if label == "velocity" else limits.max_acceleration
            raise TrajectoryLimitError(
                f"joint {j + 1} {label} {values[k, j]:.4f} {unit} at t = {times[k, j]:.4f} s exceeds the limit "
                f"{lim[j]:.4f} {unit} ({ratio[k, j]:.1%} of it)"
            )
    jerk_ratio = 0.0
    if limits.max_jerk is not None and len(traj) > 1:
        mean_jerk = np.diff(traj.accelerations, axis=0) / np.diff(traj.times)[:, None]
        j_ratio = np.abs(mean_jerk) / limits.max_jerk
        jerk_ratio = float(np.max(j_ratio))
        if jerk_ratio > 1.0 + tolerance:
            k, j = np.unravel_index(int(np.argmax(j_ratio)), j_ratio.shape)
            raise TrajectoryLimitError(
                f"joint {j + 1} jerk {mean_jerk[k, j]:.2f} rad/s³ between t = {traj.times[k]:.4f} and "
                f"{traj.times[k + 1]:.4f} s exceeds the limit {limits.max_jerk[j]:.2f} rad/s³"
            )
    for label, idx, want in (("start", 0, start), ("end", -1, goal)):
        rest = float(np.max(np.abs(traj.velocities[idx])))
        if at_rest and rest > 1e-6:
            raise TrajectoryLimitError(f"trajectory does not {label} at rest: joint speed {rest:.3g} rad/s")
        if want is not None:
            err = float(np.max(np.abs(traj.positions[idx] - joint_vector(want, traj.dof, label))))
            if err > 1e-6:
                raise TrajectoryLimitError(
                    f"trajectory {label} is {err:.3g} rad away from the requested {label}"
                )
    return LimitReport(
        position_excess_rad=max(worst, 0.0),
        velocity_ratio=float(np.max(v_ratio)),
        acceleration_ratio=float(np.max(a_ratio)),
        jerk_ratio=jerk_ratio,
        samples=int(ts.size),
    )
