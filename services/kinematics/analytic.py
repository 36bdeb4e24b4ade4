"""Closed-form kinematics for UR-structure arms (Nova5, UR5e, UR3), vectorised.

Standard DH, ``T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` with
``theta_i = q_i + offset_i``. The inverse follows Hawkins (2013): theta1 two
ways, theta5 two ways, theta6, then the planar 2-link problem for theta2/3 two
ways and theta4 — up to 8 solutions, each returned with a validity flag and
verified by FK.
"""

from __future__ import annotations

import math

import numpy as np

from services.common.errors import IKFailureError, InvalidInputError
from services.kinematics.robot_models import RobotSpec

Array = np.ndarray


def dh_matrices(spec: RobotSpec, theta: Array, i: int) -> Array:
    """Batch of DH transforms of joint i for the angles ``theta`` (any shape) → shape + (4, 4)."""
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(spec.alpha[i]), np.sin(spec.alpha[i])
    T = np.zeros((*np.shape(theta), 4, 4))
    T[..., 0, 0] = ct
    T[..., 0, 1] = -st * ca
    T[..., 0, 2] = st * sa
    T[..., 0, 3] = spec.a[i] * ct
    T[..., 1, 0] = st
    T[..., 1, 1] = ct * ca
    T[..., 1, 2] = -ct * sa
    T[..., 1, 3] = spec.a[i] * st
    T[..., 2, 1] = sa
    T[..., 2, 2] = ca
    T[..., 2, 3] = spec.d[i]
    T[..., 3, 3] = 1.0
    return T


def _inv(T: Array) -> Array:
    R = T[..., :3, :3]
    p = T[..., :3, 3]
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    Ti[..., :3, :3] = Rt
    Ti[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, p)
    Ti[..., 3, 3] = 1.0
    return Ti


def fk(spec: RobotSpec, q: Array, T_flange_tool: Array | None = None) -> Array:
    """Flange (or tool) pose in the base frame for joints ``q`` (..., 6) → (..., 4, 4)."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != spec.dof:
        raise InvalidInputError(f"{spec.name} needs {spec.dof} joint values, got {q.shape[-1]}")
    theta = q + spec.theta_offset
    T = dh_matrices(spec, theta[..., 0], 0)
    for i in range(1, spec.dof):
        T = T @ dh_matrices(spec, theta[..., i], i)
    if T_flange_tool is not None:
        T = T @ T_flange_tool
    return T


def fk_all(spec: RobotSpec, q: Array) -> Array:
    """Every joint frame 0..6 for ``q`` (6,) → (7, 4, 4); frame 0 is the base."""
    q = np.asarray(q, dtype=float)
    theta = q + spec.theta_offset
    frames = [np.eye(4)]
    for i in range(spec.dof):
        frames.append(frames[-1] @ dh_matrices(spec, theta[i], i))
    return np.stack(frames)


def ik_all(spec: RobotSpec, T_base_flange: Array, *, tol: float = 1e-6) -> tuple[Array, Array]:
    """All closed-form solutions for a batch of flange poses.

    ``T_base_flange``: (..., 4, 4). Returns ``(q, valid)`` with q of shape
    (..., 8, 6) in radians wrapped to (-pi, pi] and ``valid`` (..., 8) true where
    the branch exists and its FK reproduces the pose within ``tol`` (m / rad).
    Joint limits are not applied here (see :func:`solutions_within_limits`).
    """
    T = np.asarray(T_base_flange, dtype=float)
    if T.shape[-2:] != (4, 4):
        raise InvalidInputError(f"pose must be (..., 4, 4), got {T.shape}")
    batch = T.shape[:-2]
    a2, a3, d4, d6 = spec.a[1], spec.a[2], spec.d[3], spec.d[5]
    with np.errstate(invalid="ignore", divide="ignore"):
        R06 = T[..., :3, :3]
        p06 = T[..., :3, 3]
        p05 = p06 - d6 * R06[..., :, 2]
        # theta1 (2)
        r = np.hypot(p05[..., 0], p05[..., 1])
        phi = np.arctan2(p05[..., 1], p05[..., 0])
        psi = np.arccos(np.clip(d4 / r, -1.0, 1.0))
        ok1 = np.abs(d4) <= r + 1e-12
        th1 = np.stack([phi + psi + np.pi / 2, phi - psi + np.pi / 2], axis=-1)  # (...,2)
        s1, c1 = np.sin(th1), np.cos(th1)
        # theta5 (2 per theta1)
        num = p06[..., None, 0] * s1 - p06[..., None, 1] * c1 - d4
        cos5 = num / d6
        ok5 = np.abs(cos5) <= 1.0 + 1e-9
        th5a = np.arccos(np.clip(cos5, -1.0, 1.0))
        th5 = np.stack([th5a, -th5a], axis=-1)  # (...,2,2)
        s5 = np.sin(th5)
        # theta6 from z1 expressed in the flange frame
        z1 = np.stack([s1, -c1, np.zeros_like(s1)], axis=-1)  # (...,2,3)
        v = np.einsum("...ji,...kj->...ki", R06, z1)  # R06^T z1 → (...,2,3)
        vx = v[..., None, 0]
        vy = v[..., None, 1]
        small = np.abs(s5) < 1e-10
        th6 = np.where(small, 0.0, np.arctan2(-vy / np.where(small, 1.0, s5), vx / np.where(small, 1.0, s5)))
        # T14 = inv(T01) T06 inv(T56) inv(T45)
        T01 = dh_matrices(spec, th1, 0)[..., :, None, :, :]  # (...,2,1,4,4)
        T45 = dh_matrices(spec, th5 + spec.theta_offset[4], 4)
        T56 = dh_matrices(spec, th6 + spec.theta_offset[5], 5)
        T06 = T[..., None, None, :, :]
        T14 = _inv(T01) @ T06 @ _inv(T56) @ _inv(T45)  # (...,2,2,4,4)
        p13 = T14[..., :3, 3].copy()
        p13[..., 2] -= d4
        L2 = p13[..., 0] ** 2 + p13[..., 1] ** 2
        c3 = (L2 - a2 * a2 - a3 * a3) / (2 * a2 * a3)
        ok3 = np.abs(c3) <= 1.0 + 1e-9
        th3a = np.arccos(np.clip(c3, -1.0, 1.0))
        th3 = np.stack([th3a, -th3a], axis=-1)  # (...,2,2,2)
        th2 = np.arctan2(p13[..., None, 1], p13[..., None, 0]) - np.arctan2(
            a3 * np.sin(th3), a2 + a3 * np.cos(th3)
        )
        th234 = np.arctan2(T14[..., 1, 0], T14[..., 0, 0])[..., None]
        th4 = th234 - th2 - th3
        shape8 = (*batch, 2, 2, 2)
        theta = np.stack(
            [
                np.broadcast_to(th1[..., :, None, None], shape8),
                th2,
                th3,
                th4,
                np.broadcast_to(th5[..., None], shape8),
                np.broadcast_to(th6[..., None], shape8),
            ],
            axis=-1,
        )
        q = theta - spec.theta_offset
        q = (q + np.pi) % (2 * np.pi) - np.pi
        q = q.reshape(*batch, 8, 6)
        exists = (
            np.broadcast_to(ok1[..., None, None, None], shape8)
            & np.broadcast_to(ok5[..., :, None, None], shape8)
            & np.broadcast_to(ok3[..., None], shape8)
        ).reshape(*batch, 8)
        exists &= np.all(np.isfinite(q), axis=-1)
    q = np.where(exists[..., None], q, 0.0)
    # verify by FK
    Tq = fk(spec, q)
    pos_err = np.linalg.norm(Tq[..., :3, 3] - T[..., None, :3, 3], axis=-1)
    rot_err = np.linalg.norm(Tq[..., :3, :3] - T[..., None, :3, :3], axis=(-2, -1))
    valid = exists & (pos_err < max(tol, 1e-9)) & (rot_err < max(tol, 1e-9) * 10)
    return q, valid


def nearest_equivalent(spec: RobotSpec, q: Array, seed: Array) -> Array:
    """Shift each joint by multiples of 2π toward ``seed`` while staying within its limits."""
    q = np.asarray(q, dtype=float)
    seed = np.broadcast_to(np.asarray(seed, dtype=float), q.shape)
    k = np.round((seed - q) / (2 * np.pi))
    cand = q + 2 * np.pi * k
    # if the nearest turn is out of range, step one turn back toward the range
    too_high = cand > spec.upper
    cand = np.where(too_high, cand - 2 * np.pi, cand)
    too_low = cand < spec.lower
    cand = np.where(too_low, cand + 2 * np.pi, cand)
    return cand


def solutions_within_limits(spec: RobotSpec, T_base_flange: Array, seed: Array | None = None) -> Array:
    """Valid, in-limit solutions for one pose, each moved to the turn nearest ``seed``,
    sorted by distance to the seed (weighted max-norm). Shape (k, 6), k ≤ 8."""
    T = np.asarray(T_base_flange, dtype=float)
    if T.shape != (4, 4):
        raise InvalidInputError(f"pose must be 4x4, got {T.shape}")
    sols = ik_solutions(spec, T)
    if not sols:
        return np.zeros((0, spec.dof))
    seed_l = [0.0] * spec.dof if seed is None else [float(v) for v in np.ravel(seed)]
    lower, upper = _limits(spec)
    kept: list[tuple[float, list[float]]] = []
    # plain floats: the same as nearest_equivalent + within_limits, without numpy per-call overhead
    for q in sols:
        out = []
        for v, s, lo, hi in zip(q, seed_l, lower, upper, strict=True):
            c = v + _TWO_PI * round((s - v) / _TWO_PI)
            if c > hi:
                c -= _TWO_PI
            elif c < lo:
                c += _TWO_PI
            if not lo - 1e-9 <= c <= hi + 1e-9:
                break
            out.append(c)
        else:
            kept.append((max(abs(c - s) for c, s in zip(out, seed_l, strict=True)), out))
    kept.sort(key=lambda item: item[0])
    return np.array([q for _, q in kept]).reshape(-1, spec.dof)


def solve_nearest(spec: RobotSpec, T_base_flange: Array, seed: Array) -> Array:
    """The in-limit solution nearest the seed; IKFailureError (with the pose) when none."""
    sols = solutions_within_limits(spec, T_base_flange, seed)
    if sols.shape[0] == 0:
        p = np.asarray(T_base_flange)[:3, 3]
        raise IKFailureError(
            f"{spec.name}: no inverse-kinematics solution within joint limits for the flange at "
            f"({p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}) m"
        )
    return sols[0]


def manipulability(spec: RobotSpec, q: Array) -> float:
    """Yoshikawa measure sqrt(det(J J^T)) from the geometric Jacobian at q."""
    frames = fk_all(spec, q)
    p_end = frames[-1][:3, 3]
    J = np.zeros((6, spec.dof))
    for i in range(spec.dof):
        z = frames[i][:3, 2]
        p = frames[i][:3, 3]
        J[:3, i] = np.cross(z, p_end - p)
        J[3:, i] = z
    return float(np.sqrt(max(np.linalg.det(J @ J.T), 0.0)))


# --- scalar fast path (one pose, plain floats) -----------------------------------------------------
_CONSTS: dict[int, tuple[RobotSpec, tuple[float, ...]]] = {}
_PI = math.pi
_TWO_PI = 2.0 * math.pi


def _consts(spec: RobotSpec) -> tuple[float, ...]:
    hit = _CONSTS.get(id(spec))
    if hit is None or hit[0] is not spec:
        if len(_CONSTS) > 32:  # specs are few; bound the cache anyway
            _CONSTS.clear()
        values = (
            float(spec.d[0]),
            float(spec.a[1]),
            float(spec.a[2]),
            float(spec.d[3]),
            float(spec.d[4]),
            float(spec.d[5]),
            *(float(o) for o in spec.theta_offset),
        )
        _CONSTS[id(spec)] = (spec, values)
        return values
    return hit[1]


def _limits(spec: RobotSpec) -> tuple[list[float], list[float]]:
    return [float(v) for v in spec.lower], [float(v) for v in spec.upper]


def _wrap(a: float) -> float:
    a = math.fmod(a + _PI, _TWO_PI)
    return (a + _TWO_PI if a < 0.0 else a) - _PI


def ik_solutions(spec: RobotSpec, T_base_flange: Array, tol: float = 1e-6) -> list[tuple[float, ...]]:
    """All closed-form solutions for one flange pose, each verified by FK; plain-float fast path.

    Same branches and conventions as :func:`ik_all` (angles wrapped to (-π, π], joint
    limits not applied) but only the valid solutions, as 6-tuples, in branch order.
    Requires the UR-structure DH pattern α = (90°, 0, 0, 90°, −90°, 0), a1 = a4..6 = 0.
    """
    (r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz) = T_base_flange[:3].tolist()
    d1, a2, a3, d4, d5, d6, o1, o2, o3, o4, o5, o6 = _consts(spec)
    sin, cos, atan2, acos = math.sin, math.cos, math.atan2, math.acos
    wx = px - d6 * r02
    wy = py - d6 * r12
    r = math.hypot(wx, wy)
    if not r > abs(d4) - 1e-12 or r == 0.0:
        return []
    phi = atan2(wy, wx)
    psi = acos(max(-1.0, min(1.0, d4 / r)))
    out: list[tuple[float, ...]] = []
    ptol = max(tol, 1e-9)
    rtol = ptol * 10.0
    for th1 in (phi + psi + 0.5 * _PI, phi - psi + 0.5 * _PI):
        s1, c1 = sin(th1), cos(th1)
        c5 = (px * s1 - py * c1 - d4) / d6
        if c5 > 1.0 + 1e-9 or c5 < -1.0 - 1e-9:
            continue
        c5 = max(-1.0, min(1.0, c5))
        th5a = acos(c5)
        # R16 = R01^T R06: rows 0 and 1 needed for θ234, row 2 for θ6; p16 for the planar part
        a0, a1_, a2_ = c1 * r00 + s1 * r10, c1 * r01 + s1 * r11, c1 * r02 + s1 * r12
        b0, b1, b2 = r20, r21, r22
        e0, e1 = s1 * r00 - c1 * r10, s1 * r01 - c1 * r11
        p16x = c1 * px + s1 * py
        p16y = pz - d1
        for th5 in (th5a, -th5a):
            s5 = sin(th5)
            th6 = 0.0 if abs(s5) < 1e-10 else atan2(-e1 / s5, e0 / s5)  # wrist singular: θ6 free
            s6, c6 = sin(th6), cos(th6)
            # R14 = R16 R46^T, first column: row k · (c5 c6, -c5 s6, -s5)
            c234 = a0 * c5 * c6 - a1_ * c5 * s6 - a2_ * s5
            s234 = b0 * c5 * c6 - b1 * c5 * s6 - b2 * s5
            th234 = atan2(s234, c234)
            c234, s234 = cos(th234), sin(th234)
            x13 = p16x + c234 * d6 * s5 - s234 * d5
            y13 = p16y + s234 * d6 * s5 + c234 * d5
            c3 = (x13 * x13 + y13 * y13 - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)
            if c3 > 1.0 + 1e-9 or c3 < -1.0 - 1e-9:
                continue
            c3 = max(-1.0, min(1.0, c3))
            th3a = acos(c3)
            base = atan2(y13, x13)
            for th3 in (th3a, -th3a):
                th2 = base - atan2(a3 * sin(th3), a2 + a3 * cos(th3))
                th4 = th234 - th2 - th3
                q = (
                    _wrap(th1 - o1),
                    _wrap(th2 - o2),
                    _wrap(th3 - o3),
                    _wrap(th4 - o4),
                    _wrap(th5 - o5),
                    _wrap(th6 - o6),
                )
                if _fk_error(
                    q,
                    o1,
                    o2,
                    o3,
                    o4,
                    o5,
                    o6,
                    d1,
                    a2,
                    a3,
                    d4,
                    d5,
                    d6,
                    (r00, r01, r02, px, r10, r11, r12, py, r20, r21, r22, pz),
                    ptol,
                    rtol,
                ):
                    out.append(q)
    return out


def _fk_error(
    q: tuple[float, ...],
    o1: float,
    o2: float,
    o3: float,
    o4: float,
    o5: float,
    o6: float,
    d1: float,
    a2: float,
    a3: float,
    d4: float,
    d5: float,
    d6: float,
    target: tuple[float, ...],
    ptol: float,
    rtol: float,
) -> bool:
    """True when the closed-form FK of q reproduces the target within tolerance (independent check)."""
    sin, cos = math.sin, math.cos
    t1, t2, t3, t4, t5, t6 = q[0] + o1, q[1] + o2, q[2] + o3, q[3] + o4, q[4] + o5, q[5] + o6
    s1, c1 = sin(t1), cos(t1)
    s2, c2 = sin(t2), cos(t2)
    s23, c23 = sin(t2 + t3), cos(t2 + t3)
    s234, c234 = sin(t2 + t3 + t4), cos(t2 + t3 + t4)
    s5, c5 = sin(t5), cos(t5)
    s6, c6 = sin(t6), cos(t6)
    # FK factored as T06 = T01 · T16: with J2..J4 parallel, T16 depends on θ2, θ2+θ3, θ2+θ3+θ4,
    # θ5, θ6 only (R16 rows below; p16 = planar arm + wrist offsets)
    u00, u01, u02 = c234 * c5 * c6 - s234 * s6, -c234 * c5 * s6 - s234 * c6, -c234 * s5
    u10, u11, u12 = s234 * c5 * c6 + c234 * s6, -s234 * c5 * s6 + c234 * c6, -s234 * s5
    u20, u21, u22 = s5 * c6, -s5 * s6, c5
    x13 = a2 * c2 + a3 * c23
    y13 = a2 * s2 + a3 * s23
    p16x = x13 - c234 * d6 * s5 + s234 * d5
    p16y = y13 - s234 * d6 * s5 - c234 * d5
    p16z = d4 + d6 * c5
    (r00, r01, r02, px, r10, r11, r12, py, r20, r21, r22, pz) = target
    ep = (c1 * p16x + s1 * p16z - px) ** 2 + (s1 * p16x - c1 * p16z - py) ** 2 + (p16y + d1 - pz) ** 2
    if ep >= ptol * ptol:
        return False
    er = (
        (c1 * u00 + s1 * u20 - r00) ** 2
        + (c1 * u01 + s1 * u21 - r01) ** 2
        + (c1 * u02 + s1 * u22 - r02) ** 2
        + (s1 * u00 - c1 * u20 - r10) ** 2
        + (s1 * u01 - c1 * u21 - r11) ** 2
        + (s1 * u02 - c1 * u22 - r12) ** 2
        + (u10 - r20) ** 2
        + (u11 - r21) ** 2
        + (u12 - r22) ** 2
    )
    return er < rtol * rtol
