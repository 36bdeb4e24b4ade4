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

import math
from dataclasses import dataclass, field

import numpy as np

from services.common.errors import IKFailureError
from services.kinematics.analytic import ik_all
from services.kinematics.robot_models import RobotSpec

Array = np.ndarray

BIG = 1e9
MAX_ALTERNATIVE_TRACKS = 2  # other branches kept per path (each costs a collision check when used)


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
    # per path, the joints of its other usable tracks (other IK branches), cheapest first: a best
    # track that collides need not end the path (up to MAX_ALTERNATIVE_TRACKS of them)
    others: list[list[tuple[float, Array]]] = field(default_factory=list)  # (cost, joints)


def check_reach(spec: RobotSpec, p: Array, what: str) -> None:
    """IKFailureError naming the point when it is farther from the shoulder than the arm reaches."""
    dist = float(np.linalg.norm(p - np.array([0.0, 0.0, spec.d[0]])))
    if dist > spec.reach_m:
        raise IKFailureError(
            f"{what} at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is {dist:.3f} m from the {spec.name}'s shoulder, "
            f"beyond its reach of {spec.reach_m:.2f} m"
        )


def origin_heights(spec: RobotSpec, q: Array) -> Array:
    """Heights (base z) of the origins of joint frames 1..6 for joints (..., 6) → (..., 6), batched.

    Only the base's z row is carried through the DH chain (z_row @ A_1 @ ... @ A_i, in closed form
    per joint): a quarter of the work of the full transforms, for every sample of every track."""
    theta = np.asarray(q, dtype=float) + spec.theta_offset
    r0 = np.zeros(theta.shape[:-1])
    r1 = np.zeros(theta.shape[:-1])
    r2 = np.ones(theta.shape[:-1])
    r3 = np.zeros(theta.shape[:-1])
    out = []
    for i in range(spec.dof):
        ct, st = np.cos(theta[..., i]), np.sin(theta[..., i])
        ca, sa, a, d = math.cos(spec.alpha[i]), math.sin(spec.alpha[i]), spec.a[i], spec.d[i]
        u = r0 * ct + r1 * st  # the row against the joint's rotated x and y axes
        v = r1 * ct - r0 * st
        r0, r1, r2, r3 = u, v * ca + r2 * sa, r2 * ca - v * sa, a * u + d * r2 + r3
        out.append(r3)
    return np.stack(out, axis=-1)


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

    Only live tracks are carried from sample to sample (most die within a few samples: a branch
    outside the limits, an elbow on the wrong side), so the work shrinks with them.
    """
    T = np.asarray(T_base_flange, dtype=float)
    B, N = T.shape[:2]
    q_all, valid = ik_all(spec, T)  # (B, N, 8, 6), (B, N, 8)
    seed = np.broadcast_to(np.asarray(seed, dtype=float), (B, spec.dof))
    names = sample_names or [f"sample {k}" for k in range(N)]

    # start tracks: every solution of sample 0, moved to the turn nearest the seed
    q0 = _nearest_turn(spec, q_all[:, 0], seed[:, None, :])  # (B, 8, 6)
    alive0 = valid[:, 0] & spec.within_limits(q0)  # (B, 8)
    reason = ["" for _ in range(B)]
    fail_at = np.full(B, -1)
    for b in range(B):
        if not valid[b, 0].any():
            reason[b] = f"no IK solution at {names[0]}"
            fail_at[b] = 0
        elif not alive0[b].any():
            reason[b] = f"no IK solution within joint limits at {names[0]}"
            fail_at[b] = 0
    # the live tracks, flat (ix: index into the started tracks)
    bi, ti = np.nonzero(alive0)  # path b, track t: in (b, t) order
    started = bi.size
    ix = np.arange(started)
    prev = q0[bi, ti]  # (M, 6)
    cost = np.max(np.abs(prev - seed[bi]), axis=-1)
    margin = singularity_margin(spec, prev)
    path = np.empty((started, N, spec.dof))
    path[:, 0] = prev
    for k in range(1, N):
        if bi.size == 0:
            break
        cand = _nearest_turn(spec, q_all[bi, k], prev[:, None, :])  # (M, 8sol, 6)
        ok_sol = valid[bi, k] & spec.within_limits(cand)
        step = np.where(ok_sol, np.max(np.abs(cand - prev[:, None, :]), axis=-1), BIG)
        pick = np.argmin(step, axis=-1)
        rows = np.arange(bi.size)
        best_step = step[rows, pick]
        nxt = cand[rows, pick]
        keep = best_step <= limits.jump_threshold_rad
        if not keep.all():
            for b in np.setdiff1d(bi, bi[keep]).tolist():  # every track of path b died here
                fail_at[b] = k
                if not valid[b, k].any():
                    reason[b] = f"no IK solution at {names[k]}"
                elif not (valid[b, k] & spec.within_limits(q_all[b, k])).any() and not ok_sol[bi == b].any():
                    reason[b] = f"no IK solution within joint limits at {names[k]}"
                else:
                    reason[b] = (
                        f"the joints would jump (branch change or singularity) at {names[k]}, "
                        f"{np.degrees(np.min(best_step[bi == b])):.0f}° in one step"
                    )
        path[ix, k] = nxt
        margin = np.minimum(margin, singularity_margin(spec, nxt))
        cost = cost + best_step
        bi, ix, prev, cost, margin = bi[keep], ix[keep], nxt[keep], cost[keep], margin[keep]

    # table clearance of the elbow and wrist joints (frames 3..6) along each surviving track (only
    # those: forward kinematics of every dead track was most of the planning time)
    low = origin_heights(spec, path[ix])[..., 2:].min(axis=(-1, -2)) if ix.size else np.empty(0)
    near_table = low < limits.table_z_m + limits.arm_table_clearance_m
    singular = margin < limits.min_singularity_sin
    good = ~near_table & ~singular
    ok = np.zeros(B, dtype=bool)
    q_best = np.zeros((B, N, spec.dof))
    best_cost = np.full(B, BIG)
    others: list[list[tuple[float, Array]]] = [[] for _ in range(B)]
    for b in np.unique(bi).tolist():
        mine = np.nonzero(bi == b)[0]
        usable = mine[good[mine]]
        if usable.size == 0:
            fail_at[b] = N - 1
            if near_table[mine].all():
                reason[b] = (
                    f"every IK branch brings the elbow or wrist within {limits.arm_table_clearance_m:.2f} m "
                    f"of the table (lowest {np.max(low[mine]):.3f} m)"
                )
            else:
                reason[b] = "every IK branch passes near a wrist or elbow singularity"
            continue
        order = usable[np.argsort(cost[usable], kind="stable")]  # equal costs: in track order
        j = order[0]
        ok[b], q_best[b], best_cost[b] = True, path[ix[j]], cost[j]
        others[b] = [(float(cost[k]), path[ix[k]]) for k in order[1 : 1 + MAX_ALTERNATIVE_TRACKS]]
        reason[b] = ""
        fail_at[b] = -1
    return TrackResult(ok, q_best, best_cost, reason, fail_at, others)
