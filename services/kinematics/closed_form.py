"""The closed-form inverse of a :class:`~services.kinematics.chain.Chain` for one pose, in plain floats
(the hot path), with the polish of clipped solutions; :mod:`services.kinematics.closed_form_batch` is the
same closed form vectorised over poses.

On ``T(q) = O1 Rz(θ1) O2 Rz(θ2) … O6 Rz(θ6) O7`` it needs (:attr:`Chain.closed_form` checks it; true of both models of all three arms): O1 turns about z
only, J2 ‖ J3 ‖ J4 exactly (O3, O4 turn about z only), O5 and O6 turn about x only, and the J5→J6
offset has no x part. O2 (J1 to J2) and O7 (the flange, and the tool when one is folded in) are
general. With T1 the target seen from J1 without O7, n = Rz(θ1) O2 e_z the J2–J4 axis:

1. the offset of the flange along n is fixed: n·(p_T1 − μ z_T1) = δ, i.e. A cos θ1 + B sin θ1 = C:
   two θ1 (the shoulder branches);
2. n seen from the flange depends on θ5, θ6 alone: its z part gives cos θ5 and its xy part
   |sin θ5| (two θ5, the wrist branches; atan2 of the two stays accurate next to the wrist
   singularity, where acos would lose half the digits), its xy angle θ6;
3. what is left after Rz(θ2) is a planar 2-link arm: two θ3 (the elbow branches), θ2, θ4.

Up to 8 solutions, exact to rounding (≤ 1e-11 m, ~1e-15 rad on the arm's model, also next to a
singularity) with no check needed. Only a cosine that comes out beyond ±1 by more than rounding (a
pose at a boundary, e.g. the wrist at θ5 = ±π with the elbow folded, where θ6 is ill-determined but
the elbow cannot take up its error, or a pose up to 1e-6 beyond the workspace) is clipped; that
solution is refined by Gauss–Newton steps on the chain (minimum-norm, so the singular Jacobian
there does no harm) and kept if it then reproduces the pose within ``tol`` (for a reachable pose:
exactly). Solutions within :data:`SINGULAR_RAD` of the shoulder, elbow or wrist singularity carry a
:class:`~services.kinematics.analytic.Singularity` flag, and two of them closer than :data:`DUPLICATE_RAD` are returned once.
"""

from __future__ import annotations

import math

import numpy as np

from services.common.errors import ConfigurationError, InvalidInputError
from services.kinematics.chain import Chain, ClosedForm, rz

Array = np.ndarray

# A solution whose branch pair is this close to meeting (the sine of the half-angle between the
# pair: ψ for the shoulder, θ3 for the elbow, the J6-to-J2 axis angle for the wrist) is flagged.
SINGULAR_RAD = 1e-6
# A cosine up to this far beyond ±1 is clipped (the pose is at, or a hair beyond, a boundary) and
# the solution polished and checked on the chain; farther, the branch does not exist.
CLIP_SLACK = 1e-6
# Beyond ±1 by no more than this is rounding: the clipped solution is exact without a check.
ROUNDING = 1e-12
# Two solutions flagged at the same singularity and closer than this in every joint are one solution
# (both exact): the branches that meet there, apart by rounding only (θ3 = ±acos(−1 + 1e-16) ≈ ±1e-8).
DUPLICATE_RAD = 1e-6
_POLISH_STEPS = 12  # Gauss–Newton steps for a clipped solution (quadratic: 3-4 suffice off a singularity)
_PI = math.pi
_TWO_PI = 2.0 * math.pi


Solution = tuple[
    float, tuple[float, ...], int, bool
]  # (distance to the seed, joints, singular bits, clipped)


def _closed_form(
    cf: ClosedForm,
    rows: list[list[float]],
    seed: list[float] | None,
    lower: list[float],
    upper: list[float],
) -> tuple[list[Solution], bool, bool]:
    """Every branch for one pose (rows of T, at least 3), whether any was clipped, any singular.

    Without a seed, joints are wrapped to [-π, π) and limits are not applied (distance 0). With
    one, each joint is the value nearest the seed, shifted by a turn into [lower, upper] when it
    is outside, and the branch is dropped when that fails (1e-9) — checked as soon as the joint is
    known, so an out-of-limit θ1 skips its whole subtree; the distance is the max-norm to the seed.
    """
    (r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz) = rows[0], rows[1], rows[2]
    sin, cos, atan2, acos, sqrt = math.sin, math.cos, math.atan2, math.acos, math.sqrt
    tau = _TWO_PI
    o1, o2, o3, o4, o5, o6 = cf.offsets
    limited = seed is not None
    if seed is None:
        s1 = s2 = s3 = s4 = s5 = s6 = 0.0
    else:
        s1, s2, s3, s4, s5, s6 = seed
    # joint i is reported as (θ_i − k_i) mod 2π + b_i: the value within π of the seed
    b1, b2, b3, b4, b5, b6 = s1 - _PI, s2 - _PI, s3 - _PI, s4 - _PI, s5 - _PI, s6 - _PI
    k1, k2, k3, k4, k5, k6 = o1 + b1, o2 + b2, o3 + b3, o4 + b4, o5 + b5, o6 + b6
    # limits l..h, checked as le..he (1e-9 slack); only the elbow joints (2-4, checked per solution)
    # are skipped when their whole window [seed − π, seed + π] lies within the limits
    if limited:
        l1, l2, l3, l4, l5, l6 = lower
        h1, h2, h3, h4, h5, h6 = upper
        le1, le2, le3, le4, le5, le6 = l1 - 1e-9, l2 - 1e-9, l3 - 1e-9, l4 - 1e-9, l5 - 1e-9, l6 - 1e-9
        he1, he2, he3, he4, he5, he6 = h1 + 1e-9, h2 + 1e-9, h3 + 1e-9, h4 + 1e-9, h5 + 1e-9, h6 + 1e-9
        check2 = not (l2 <= b2 and b2 + tau <= h2)
        check3 = not (l3 <= b3 and b3 + tau <= h3)
        check4 = not (l4 <= b4 and b4 + tau <= h4)
    else:
        l1 = l2 = l3 = l4 = l5 = l6 = h1 = h2 = h3 = h4 = h5 = h6 = 0.0
        le1 = le2 = le3 = le4 = le5 = le6 = he1 = he2 = he3 = he4 = he5 = he6 = 0.0
        check2 = check3 = check4 = False
    r7 = cf.r7
    if r7 is not None:  # T' = T O7⁻¹: rotation R R7ᵀ
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = (
            r00 * r7[0] + r01 * r7[1] + r02 * r7[2],
            r00 * r7[3] + r01 * r7[4] + r02 * r7[5],
            r00 * r7[6] + r01 * r7[7] + r02 * r7[8],
            r10 * r7[0] + r11 * r7[1] + r12 * r7[2],
            r10 * r7[3] + r11 * r7[4] + r12 * r7[5],
            r10 * r7[6] + r11 * r7[7] + r12 * r7[8],
            r20 * r7[0] + r21 * r7[1] + r22 * r7[2],
            r20 * r7[3] + r21 * r7[4] + r22 * r7[5],
            r20 * r7[6] + r21 * r7[7] + r22 * r7[8],
        )
    t7x, t7y, t7z = cf.t7
    # T1 = O1⁻¹ T O7⁻¹ (O1 a translation): p1 = p − R' t7 − t1
    px -= r00 * t7x + r01 * t7y + r02 * t7z + cf.t1x
    py -= r10 * t7x + r11 * t7y + r12 * t7z + cf.t1y
    pz -= r20 * t7x + r21 * t7y + r22 * t7z + cf.t1z
    # 1. shoulder: n·(p1 − μ z1) = δ with n = Rz(θ1) u
    mu, ux, uy, uz = cf.mu, cf.ux, cf.uy, cf.uz
    ax, ay, az = px - mu * r02, py - mu * r12, pz - mu * r22
    A = ux * ax + uy * ay
    B = ux * ay - uy * ax
    rho = math.hypot(A, B)
    if not rho > 0.0:  # the target on the J1 axis (or NaN): θ1 is free, no closed form
        return [], False, False
    c = (cf.delta - uz * az) / rho
    clipped1 = False
    if not -1.0 <= c <= 1.0:
        if not abs(c) <= 1.0 + CLIP_SLACK:
            return [], False, False
        clipped1 = abs(c) > 1.0 + ROUNDING
        c = 1.0 if c > 0.0 else -1.0
    psi = acos(c)
    flag1 = 1 if sqrt(1.0 - c * c) < SINGULAR_RAD else 0
    base1 = atan2(B, A)
    a00, a01, a02, a10, a11, a12, a20, a21, a22 = cf.r2
    t2x, t2y, t2z = cf.t2x, cf.t2y, cf.t2z
    ca5, sa5, ca6, sa6 = cf.ca5, cf.sa5, cf.ca6, cf.sa6
    k5s = -sa5 * sa6
    abs_sa5 = abs(sa5)
    c56 = ca5 * ca6
    tau5x, tau5y, tau5z = cf.tau5
    tau6x, tau6y, tau6z = cf.tau6
    L3, L4, beta3, d34 = cf.l3, cf.l4, cf.beta3, cf.beta3 - cf.beta4
    L33_44, L34 = L3 * L3 + L4 * L4, 2.0 * L3 * L4
    out: list[Solution] = []
    any_clipped = any_singular = False
    for th1 in (base1 + psi, base1 - psi):
        v1 = (th1 - k1) % tau + b1
        if limited:
            if v1 > h1:
                v1 -= tau
            elif v1 < l1:
                v1 += tau
            if not le1 <= v1 <= he1:
                continue
        far1 = v1 - s1 if v1 > s1 else s1 - v1  # the max-norm distance to the seed, built up inline
        c1, s1_ = cos(th1), sin(th1)
        # Q = Rz(−θ1) T1, then M = O2⁻¹ Q: M = R2ᵀ R_Q, p_M = R2ᵀ (p_Q − t2)
        q00, q01, q02 = c1 * r00 + s1_ * r10, c1 * r01 + s1_ * r11, c1 * r02 + s1_ * r12
        q10, q11, q12 = c1 * r10 - s1_ * r00, c1 * r11 - s1_ * r01, c1 * r12 - s1_ * r02
        qx, qy, qz = c1 * px + s1_ * py - t2x, c1 * py - s1_ * px - t2y, pz - t2z
        m00 = a00 * q00 + a10 * q10 + a20 * r20
        m01 = a00 * q01 + a10 * q11 + a20 * r21
        m02 = a00 * q02 + a10 * q12 + a20 * r22
        m10 = a01 * q00 + a11 * q10 + a21 * r20
        m11 = a01 * q01 + a11 * q11 + a21 * r21
        m12 = a01 * q02 + a11 * q12 + a21 * r22
        m20 = a02 * q00 + a12 * q10 + a22 * r20
        m21 = a02 * q01 + a12 * q11 + a22 * r21
        m22 = a02 * q02 + a12 * q12 + a22 * r22
        pm0 = a00 * qx + a10 * qy + a20 * qz
        pm1 = a01 * qx + a11 * qy + a21 * qz
        # 2. wrist: (m20, m21, m22) is n seen from the flange; its z part fixes θ5
        c5 = (m22 - c56) / k5s
        clipped5 = clipped1
        if not -1.0 <= c5 <= 1.0:
            if not abs(c5) <= 1.0 + CLIP_SLACK:
                continue
            clipped5 = clipped5 or abs(c5) > 1.0 + ROUNDING
            c5 = 1.0 if c5 > 0.0 else -1.0
        # sin θ5 from the xy part of n (its size is |sin θ5| sin α5 beside a tiny term): accurate where
        # acos(c5) is not, next to the wrist singularity
        ky0 = ca6 * sa5 * c5 + sa6 * ca5
        s5a = sqrt(max(0.0, m20 * m20 + m21 * m21 - ky0 * ky0)) / abs_sa5
        th5a = atan2(s5a, c5)
        r5 = math.hypot(s5a, c5)
        c5, s5a = c5 / r5, s5a / r5
        n_angle = atan2(m21, m20)
        for th5, sn5 in ((th5a, s5a), (-th5a, -s5a)):
            v5 = (th5 - k5) % tau + b5
            if limited:
                if v5 > h5:
                    v5 -= tau
                elif v5 < l5:
                    v5 += tau
                if not le5 <= v5 <= he5:
                    continue
            # k = Rx(−α6) Rz(−θ5) Rx(−α5) e_z: n seen from the flange before θ6 turns it
            kx, ky = sn5 * sa5, ca6 * sa5 * c5 + sa6 * ca5
            flag5 = flag1 | (4 if math.hypot(kx, ky) < SINGULAR_RAD else 0)
            th6 = atan2(ky, kx) - n_angle
            v6 = (th6 - k6) % tau + b6
            if limited:
                if v6 > h6:
                    v6 -= tau
                elif v6 < l6:
                    v6 += tau
                if not le6 <= v6 <= he6:
                    continue
            far6 = far1
            if limited:
                d = v5 - s5
                if d > far6:
                    far6 = d
                elif -d > far6:
                    far6 = -d
                d = v6 - s6
                if d > far6:
                    far6 = d
                elif -d > far6:
                    far6 = -d
            c6, sn6 = cos(th6), sin(th6)
            # f = W⁻¹ e_x and g = W⁻¹ p_W (W = O5 Rz(θ5) O6 Rz(θ6)): the planar pose is M W⁻¹
            X, Y, Z = c5, -ca6 * sn5, sa6 * sn5
            fx, fy, fz = c6 * X + sn6 * Y, c6 * Y - sn6 * X, Z
            X, Y = c5 * tau5x + sn5 * tau5y + tau6x, c5 * tau5y - sn5 * tau5x
            Y, Z = ca6 * Y + sa6 * tau5z + tau6y, ca6 * tau5z - sa6 * Y + tau6z
            gx, gy = c6 * X + sn6 * Y, c6 * Y - sn6 * X
            phi = atan2(m10 * fx + m11 * fy + m12 * fz, m00 * fx + m01 * fy + m02 * fz)
            x = pm0 - (m00 * gx + m01 * gy + m02 * Z)
            y = pm1 - (m10 * gx + m11 * gy + m12 * Z)
            # 3. elbow: the planar 2-link arm to (x, y)
            c3 = (x * x + y * y - L33_44) / L34
            clipped = clipped5
            if not -1.0 <= c3 <= 1.0:
                if not abs(c3) <= 1.0 + CLIP_SLACK:
                    continue
                clipped = clipped or abs(c3) > 1.0 + ROUNDING
                c3 = 1.0 if c3 > 0.0 else -1.0
            se = sqrt(1.0 - c3 * c3)
            flags = flag5 | (2 if se < SINGULAR_RAD else 0)
            any_clipped = any_clipped or clipped
            any_singular = any_singular or flags != 0
            eps = acos(c3)
            base2 = atan2(y, x) - beta3
            lc = L3 + L4 * c3
            for ep, s_e in ((eps, se), (-eps, -se)):
                th2 = base2 - atan2(L4 * s_e, lc)
                th3 = ep + d34
                v2 = (th2 - k2) % tau + b2
                v3 = (th3 - k3) % tau + b3
                v4 = (phi - th2 - th3 - k4) % tau + b4
                if check2:
                    if v2 > h2:
                        v2 -= tau
                    elif v2 < l2:
                        v2 += tau
                    if not le2 <= v2 <= he2:
                        continue
                if check3:
                    if v3 > h3:
                        v3 -= tau
                    elif v3 < l3:
                        v3 += tau
                    if not le3 <= v3 <= he3:
                        continue
                if check4:
                    if v4 > h4:
                        v4 -= tau
                    elif v4 < l4:
                        v4 += tau
                    if not le4 <= v4 <= he4:
                        continue
                far = far6
                if limited:
                    d = v2 - s2
                    if d > far:
                        far = d
                    elif -d > far:
                        far = -d
                    d = v3 - s3
                    if d > far:
                        far = d
                    elif -d > far:
                        far = -d
                    d = v4 - s4
                    if d > far:
                        far = d
                    elif -d > far:
                        far = -d
                out.append((far, (v1, v2, v3, v4, v5, v6), flags, clipped))
    return out, any_clipped, any_singular


def _residual(ch: Chain, q: Array, T: Array) -> tuple[Array, float, float, Array]:
    """(error twist [dp, dw] in the base frame, position error m, rotation error rad, Jacobian 6×6)."""
    F = ch.origins[0]
    axes, points = [], []
    for i in range(6):
        F = F @ rz(q[i] + ch.offsets[i])
        axes.append(F[:3, 2])
        points.append(F[:3, 3])
        F = F @ ch.origins[i + 1]
    dp = T[:3, 3] - F[:3, 3]
    dR = T[:3, :3] @ F[:3, :3].T
    w = 0.5 * np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]])
    sw = float(np.linalg.norm(w))
    angle = math.atan2(sw, (float(np.trace(dR)) - 1.0) / 2.0)
    dw = w * (angle / sw) if sw > 0.0 else w  # the rotation vector of dR
    z = np.array(axes)
    J = np.vstack([np.cross(z, F[:3, 3] - np.array(points)).T, z.T])
    return np.concatenate([dp, dw]), float(np.linalg.norm(dp)), angle, J


def polish(ch: Chain, q0: tuple[float, ...], T: Array) -> tuple[tuple[float, ...], float, float]:
    """Gauss–Newton on the chain from a clipped closed-form solution: (joints, position error m,
    rotation error rad). Minimum-norm steps (least squares), so a Jacobian that is singular there
    (the pose sits on a boundary) does no harm, each step shortened until it lowers the error, so
    a pose just beyond reach (no exact solution) keeps the nearest configuration found; for a
    reachable pose this ends exact to rounding."""
    q = np.asarray(q0, dtype=float)
    e, pos, rot, J = _residual(ch, q, T)
    for _ in range(_POLISH_STEPS):
        if pos < 1e-14 and rot < 1e-14:
            break
        step = np.linalg.lstsq(J, e, rcond=1e-12)[0]
        for _ in range(6):
            trial = _residual(ch, q + step, T)
            if trial[1] + trial[2] < pos + rot:
                break
            step *= 0.25
        else:
            break  # no step lowers the error: as near as it gets
        q = q + step
        e, pos, rot, J = trial
    return tuple(q.tolist()), pos, rot


def _refined(
    ch: Chain, sol: Solution, T: Array, tol: float, lower: list[float], upper: list[float]
) -> Solution | None:
    """A clipped solution polished on the chain; None when it does not reach the pose within tol
    (or the polish left the limits, when ``lower``/``upper`` are given)."""
    q, pos, rot = polish(ch, sol[1], T)
    if not (pos < tol and rot < tol):
        return None
    if lower and not all(lo - 1e-9 <= v <= hi + 1e-9 for v, lo, hi in zip(q, lower, upper, strict=True)):
        return None
    if not lower:
        q = tuple((v + _PI) % _TWO_PI - _PI for v in q)
    return (sol[0], q, sol[2], False)


def _same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return all(abs((x - y + _PI) % _TWO_PI - _PI) < DUPLICATE_RAD for x, y in zip(a, b, strict=True))


_NO_LIMITS: list[float] = []


def solve(
    ch: Chain,
    T: Array,
    tol: float,
    seed: list[float] | None = None,
    lower: list[float] = _NO_LIMITS,
    upper: list[float] = _NO_LIMITS,
) -> list[Solution]:
    """Every solution of one pose (see :func:`_closed_form`), clipped ones checked, duplicates dropped."""
    cf = ch.closed_form
    if cf is None:
        raise ConfigurationError(f"{ch.name} lacks the structure of the closed form")
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4):
        raise InvalidInputError(f"pose must be 4x4, got {T.shape}")
    sols, any_clipped, any_singular = _closed_form(cf, T.tolist(), seed, lower, upper)
    if any_clipped:  # a pose at a boundary: polish the clipped solutions, keep those that reach it
        tol = max(tol, 1e-9)
        refined = [s if not s[3] else _refined(ch, s, T, tol, lower, upper) for s in sols]
        sols = [s for s in refined if s is not None]
    if any_singular:  # only at a singularity can two branches be one solution
        kept: list[Solution] = []
        for s in sols:
            if not (s[2] and any(k[2] & s[2] and _same(s[1], k[1]) for k in kept)):
                kept.append(s)
        return kept
    return sols


def solve_within_limits(
    ch: Chain,
    T: Array,
    seed: Array | list[float] | None,
    lower: list[float],
    upper: list[float],
    tol: float = 1e-6,
) -> Array:
    """In-limit solutions of the chain for pose T, each on the turn nearest ``seed`` (zeros when
    None), sorted by max-norm distance to it: (k, 6), k ≤ 8."""
    seed_l = [0.0] * 6 if seed is None else (seed if isinstance(seed, list) else np.ravel(seed).tolist())
    sols = solve(ch, T, tol, seed_l, lower, upper)
    if not sols:
        return np.zeros((0, 6))
    sols.sort()  # by distance first (ties: by joints, deterministic)
    return np.array([s[1] for s in sols])
