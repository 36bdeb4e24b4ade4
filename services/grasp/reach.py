"""Reachability with the closed-form IK, batched: which tool paths the arm can follow in one branch.

A tool path (poses densely sampled along straight lines) is followed by *tracking*: start
from each in-limit IK solution of the first pose, then at every next sample take the valid,
in-limit solution nearest the previous one. A step larger than the jump threshold means the
arm would change branch or pass a singularity between samples: that track dies. Surviving
tracks are also checked for the elbow and wrist staying above the table and for a margin from
the wrist (q5) and elbow (q3) singularities. All numpy, batched over many candidate paths at
once — grasp options are compared by running them side by side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.errors import IKFailureError
from services.kinematics.analytic import dh_matrices, ik_all
from services.kinematics.robot_models import RobotSpec

Array = np.ndarray

BIG = 1e9


@dataclass(frozen=True)
class TrackLimits:
    jump_threshold_rad: float = np.radians(10.0)
    min_singularity_sin: float = np.sin(np.radians(3.0))
    arm_table_clearance_m: float = 0.08
    table_z_m: float = 0.0


@dataclass
class TrackResult:
    """Best track per path (batch entry): joints along it, cost, and why paths failed."""

    ok: Array  # (B,) bool
    q: Array  # (B, N, 6): joints along the best track (garbage where not ok)
    cost: Array  # (B,) sum of per-step max joint change, plus the move from the seed
    reason: list[str]  # per path: "" when ok, else why not
    fail_index: Array  # (B,) sample index where the last track died (-1 when ok)


def check_reach(spec: RobotSpec, p: Array, what: str) -> None:
    """IKFailureError naming the point when it is farther from the shoulder than the arm reaches."""
    dist = float(np.linalg.norm(p - np.array([0.0, 0.0, spec.d[0]])))
    if dist > spec.reach_m:
        raise IKFailureError(
            f"{what} at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is {dist:.3f} m from the {spec.name}'s shoulder, "
            f"beyond its reach of {spec.reach_m:.2f} m"
        )


def frame_origins(spec: RobotSpec, q: Array) -> Array:
    """Origins of joint frames 1..6 for joints (..., 6) → (..., 6, 3), batched."""
    theta = np.asarray(q, dtype=float) + spec.theta_offset
    T = dh_matrices(spec, theta[..., 0], 0)
    out = [T[..., :3, 3]]
    for i in range(1, spec.dof):
        T = T @ dh_matrices(spec, theta[..., i], i)
        out.append(T[..., :3, 3])
    return np.stack(out, axis=-2)


def singularity_margin(spec: RobotSpec, q: Array) -> Array:
    """min(|sin θ3|, |sin θ5|): 0 at the elbow-stretched or wrist-aligned singularities."""
    theta = np.asarray(q, dtype=float) + spec.theta_offset
    return np.minimum(np.abs(np.sin(theta[..., 2])), np.abs(np.sin(theta[..., 4])))


def _nearest_turn(spec: RobotSpec, q: Array, ref: Array) -> Array:
    """Shift q by whole turns toward ref, then back inside the limits where one turn allows."""
    k = np.round((ref - q) / (2 * np.pi))
    cand = q + 2 * np.pi * k
    cand = np.where(cand > spec.upper, cand - 2 * np.pi, cand)
    return np.where(cand < spec.lower, cand + 2 * np.pi, cand)


def track_paths(
    spec: RobotSpec,
    T_base_flange: Array,
    seed: Array,
    limits: TrackLimits,
    sample_names: list[str] | None = None,
) -> TrackResult:
    """Follow B paths of N flange poses each (B, N, 4, 4) in one IK branch, from ``seed`` (6,) or (B, 6).

    Cost = max-norm move from the seed to the first sample + Σ per-step max-norm joint change
    (a proxy for motion time at equal joint speeds). ``sample_names`` (length N) name the
    samples in failure reasons.
    """
    T = np.asarray(T_base_flange, dtype=float)
    B, N = T.shape[:2]
    q_all, valid = ik_all(spec, T)  # (B, N, 8, 6), (B, N, 8)
    seed = np.broadcast_to(np.asarray(seed, dtype=float), (B, spec.dof))[:, None, :]
    names = sample_names or [f"sample {k}" for k in range(N)]

    # start tracks: every solution of sample 0, moved to the turn nearest the seed
    q0 = _nearest_turn(spec, q_all[:, 0], seed)  # (B, 8, 6)
    alive = valid[:, 0] & spec.within_limits(q0)  # (B, 8)
    reason = ["" for _ in range(B)]
    fail_at = np.full(B, -1)
    for b in range(B):
        if not valid[b, 0].any():
            reason[b] = f"no IK solution at {names[0]}"
            fail_at[b] = 0
        elif not alive[b].any():
            reason[b] = f"no IK solution within joint limits at {names[0]}"
            fail_at[b] = 0
    cost = np.where(alive, np.max(np.abs(q0 - seed), axis=-1), BIG)
    path = np.empty((B, 8, N, 6))
    path[:, :, 0] = q0
    min_margin = singularity_margin(spec, q0)
    prev = q0
    for k in range(1, N):
        cand = _nearest_turn(spec, q_all[:, k, None, :, :], prev[:, :, None, :])  # (B, 8tr, 8sol, 6)
        ok_sol = valid[:, k, None, :] & spec.within_limits(cand)
        step = np.max(np.abs(cand - prev[:, :, None, :]), axis=-1)
        step = np.where(ok_sol, step, BIG)
        pick = np.argmin(step, axis=-1)  # (B, 8)
        best_step = np.take_along_axis(step, pick[..., None], axis=-1)[..., 0]
        nxt = np.take_along_axis(cand, pick[..., None, None], axis=2)[:, :, 0]
        was_alive = alive
        alive = alive & (best_step <= limits.jump_threshold_rad)
        died = was_alive.any(axis=1) & ~alive.any(axis=1)
        for b in np.nonzero(died)[0].tolist():
            fail_at[b] = k
            if not valid[b, k].any():
                reason[b] = f"no IK solution at {names[k]}"
            elif not (valid[b, k] & spec.within_limits(q_all[b, k])).any() and not ok_sol[b].any():
                reason[b] = f"no IK solution within joint limits at {names[k]}"
            else:
                reason[b] = (
                    f"the joints would jump (branch change or singularity) at {names[k]}, "
                    f"{np.degrees(np.min(best_step[b])):.0f}° in one step"
                )
        cost = np.where(alive, cost + best_step, BIG)
        path[:, :, k] = nxt
        min_margin = np.minimum(min_margin, singularity_margin(spec, nxt))
        prev = nxt

    # table clearance of the elbow and wrist joints (frames 3..6) along each surviving track (only
    # those: forward kinematics of every dead track was most of the planning time)
    low = np.full((B, 8), np.inf)
    live = np.nonzero(alive)
    if live[0].size:
        low[live] = frame_origins(spec, path[live])[..., 2:, 2].min(axis=(-1, -2))  # (M, N, 4) → (M,)
    near_table = low < limits.table_z_m + limits.arm_table_clearance_m
    singular = min_margin < limits.min_singularity_sin
    for b in range(B):
        if alive[b].any() and not (alive[b] & ~near_table[b] & ~singular[b]).any():
            fail_at[b] = N - 1
            if near_table[b][alive[b]].all():
                reason[b] = (
                    f"every IK branch brings the elbow or wrist within {limits.arm_table_clearance_m:.2f} m "
                    f"of the table (lowest {np.max(np.where(alive[b], low[b], -BIG)):.3f} m)"
                )
            else:
                reason[b] = "every IK branch passes near a wrist or elbow singularity"
    alive &= ~near_table & ~singular
    cost = np.where(alive, cost, BIG)
    best = np.argmin(cost, axis=1)
    ok = alive[np.arange(B), best]
    q_best = path[np.arange(B), best]
    for b in np.nonzero(ok)[0].tolist():
        reason[b] = ""
        fail_at[b] = -1
    return TrackResult(ok, q_best, cost[np.arange(B), best], reason, fail_at)
