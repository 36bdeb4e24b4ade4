"""The closed form of :mod:`services.kinematics.closed_form`, vectorised over a batch of poses: all 8
branches of every pose at once, the clipped ones polished one by one."""

from __future__ import annotations

import numpy as np

from services.common.errors import ConfigurationError, InvalidInputError
from services.kinematics.chain import Chain, ClosedForm
from services.kinematics.closed_form import CLIP_SLACK, ROUNDING, SINGULAR_RAD, polish

Array = np.ndarray


def _clip(c: Array) -> tuple[Array, Array, Array]:
    """(clipped cosine, exists: within CLIP_SLACK of [-1, 1], clipped beyond rounding)."""
    a = np.abs(c)
    return np.clip(c, -1.0, 1.0), a <= 1.0 + CLIP_SLACK, a > 1.0 + ROUNDING


def _closed_form_batch(cf: ClosedForm, T: Array) -> tuple[Array, Array, Array, Array]:
    """All 8 branches of every pose T (..., 4, 4): joints (..., 8, 6) unwrapped, exists, clipped,
    singularity bits (..., 8). The same steps as the single-pose closed form."""
    R = T[..., :3, :3]
    if cf.r7 is not None:
        R = R @ np.array(cf.r7).reshape(3, 3).T
    p = T[..., :3, 3] - R @ np.array(cf.t7) - np.array([cf.t1x, cf.t1y, cf.t1z])
    a = p - cf.mu * R[..., :, 2]
    A = cf.ux * a[..., 0] + cf.uy * a[..., 1]
    B = cf.ux * a[..., 1] - cf.uy * a[..., 0]
    rho = np.hypot(A, B)
    c, ok1, clip1 = _clip((cf.delta - cf.uz * a[..., 2]) / np.where(rho > 0, rho, np.nan))
    psi = np.arccos(c)
    flag1 = np.where(np.sqrt(1.0 - c * c) < SINGULAR_RAD, 1, 0)
    base1 = np.arctan2(B, A)
    th1 = np.stack([base1 + psi, base1 - psi], axis=-1)  # (..., 2)
    c1, s1 = np.cos(th1)[..., None], np.sin(th1)[..., None]
    rows = R[..., None, 0, :], R[..., None, 1, :], R[..., None, 2, :]  # (..., 1, 3)
    Q = (
        c1 * rows[0] + s1 * rows[1],
        c1 * rows[1] - s1 * rows[0],
        np.broadcast_to(rows[2], c1.shape[:-1] + (3,)),
    )
    px, py, pz = p[..., None, 0], p[..., None, 1], p[..., None, 2]
    c1, s1 = c1[..., 0], s1[..., 0]
    pq = (c1 * px + s1 * py - cf.t2x, c1 * py - s1 * px - cf.t2y, np.broadcast_to(pz - cf.t2z, c1.shape))
    r2 = cf.r2
    M = [r2[i] * Q[0] + r2[3 + i] * Q[1] + r2[6 + i] * Q[2] for i in range(3)]  # rows of R2ᵀ R_Q, (..., 2, 3)
    pm = [r2[i] * pq[0] + r2[3 + i] * pq[1] + r2[6 + i] * pq[2] for i in range(2)]
    c5, ok5, clip5 = _clip((M[2][..., 2] - cf.ca5 * cf.ca6) / (-cf.sa5 * cf.sa6))  # (..., 2)
    ky0 = cf.ca6 * cf.sa5 * c5 + cf.sa6 * cf.ca5
    s5a = np.sqrt(np.maximum(0.0, M[2][..., 0] ** 2 + M[2][..., 1] ** 2 - ky0**2)) / abs(cf.sa5)
    th5a = np.arctan2(s5a, c5)
    r5 = np.hypot(s5a, c5)
    th5 = np.stack([th5a, -th5a], axis=-1)  # (..., 2, 2)
    s5, c5 = np.stack([s5a / r5, -s5a / r5], axis=-1), (c5 / r5)[..., None]
    kx, ky = s5 * cf.sa5, cf.ca6 * cf.sa5 * c5 + cf.sa6 * cf.ca5
    flag5 = flag1[..., None, None] | np.where(np.hypot(kx, ky) < SINGULAR_RAD, 4, 0)
    th6 = np.arctan2(ky, kx) - np.arctan2(M[2][..., 1], M[2][..., 0])[..., None]
    c6, s6 = np.cos(th6), np.sin(th6)
    X, Y, Z = c5, -cf.ca6 * s5, cf.sa6 * s5
    f = (c6 * X + s6 * Y, c6 * Y - s6 * X, Z)
    t5x, t5y, t5z = cf.tau5
    X, Y = c5 * t5x + s5 * t5y + cf.tau6[0], c5 * t5y - s5 * t5x
    Y, Z = cf.ca6 * Y + cf.sa6 * t5z + cf.tau6[1], cf.ca6 * t5z - cf.sa6 * Y + cf.tau6[2]
    g = (c6 * X + s6 * Y, c6 * Y - s6 * X, Z)
    Mw = [[M[i][..., None, j] for j in range(3)] for i in range(3)]  # (..., 2, 1) each
    phi = np.arctan2(
        Mw[1][0] * f[0] + Mw[1][1] * f[1] + Mw[1][2] * f[2],
        Mw[0][0] * f[0] + Mw[0][1] * f[1] + Mw[0][2] * f[2],
    )
    x = pm[0][..., None] - (Mw[0][0] * g[0] + Mw[0][1] * g[1] + Mw[0][2] * g[2])
    y = pm[1][..., None] - (Mw[1][0] * g[0] + Mw[1][1] * g[1] + Mw[1][2] * g[2])
    c3, ok3, clip3 = _clip((x * x + y * y - cf.l3**2 - cf.l4**2) / (2.0 * cf.l3 * cf.l4))  # (..., 2, 2)
    se = np.sqrt(1.0 - c3 * c3)
    flags = flag5 | np.where(se < SINGULAR_RAD, 2, 0)
    eps = np.arccos(c3)
    sign = np.array([1.0, -1.0])
    e, s_e = eps[..., None] * sign, se[..., None] * sign  # (..., 2, 2, 2)
    th2 = (np.arctan2(y, x) - cf.beta3)[..., None] - np.arctan2(cf.l4 * s_e, (cf.l3 + cf.l4 * c3)[..., None])
    th3 = e + (cf.beta3 - cf.beta4)
    th4 = phi[..., None] - th2 - th3
    shape8 = th2.shape
    o = cf.offsets
    q = np.stack(
        [
            np.broadcast_to(th1[..., :, None, None], shape8) - o[0],
            th2 - o[1],
            th3 - o[2],
            th4 - o[3],
            np.broadcast_to(th5[..., None], shape8) - o[4],
            np.broadcast_to(th6[..., None], shape8) - o[5],
        ],
        axis=-1,
    )
    batch = T.shape[:-2]
    exists = np.broadcast_to(ok1[..., None, None, None] & ok5[..., :, None, None] & ok3[..., None], shape8)
    clipped = np.broadcast_to(
        clip1[..., None, None, None] | clip5[..., :, None, None] | clip3[..., None], shape8
    )
    flags = np.broadcast_to(flags[..., None], shape8)
    exists = exists.reshape(*batch, 8) & np.all(np.isfinite(q.reshape(*batch, 8, 6)), axis=-1)
    return q.reshape(*batch, 8, 6), exists, clipped.reshape(*batch, 8), flags.reshape(*batch, 8)


def chain_ik_all(ch: Chain, T_base_flange: Array, tol: float) -> tuple[Array, Array, Array]:
    cf = ch.closed_form
    if cf is None:
        raise ConfigurationError(f"{ch.name} lacks the structure of the closed form")
    T = np.asarray(T_base_flange, dtype=float)
    if T.shape[-2:] != (4, 4):
        raise InvalidInputError(f"pose must be (..., 4, 4), got {T.shape}")
    with np.errstate(invalid="ignore", divide="ignore"):
        q, exists, clipped, flags = _closed_form_batch(cf, T)
    q = np.where(exists[..., None], (q + np.pi) % (2 * np.pi) - np.pi, 0.0)
    valid = exists.copy()
    check = exists & clipped
    if check.any():  # poses at a boundary: polish the clipped solutions, keep those that reach it
        tol = max(tol, 1e-9)
        Tt = np.broadcast_to(T[..., None, :, :], (*exists.shape, 4, 4))
        for idx in zip(*np.nonzero(check), strict=True):
            qi, pos, rot = polish(ch, tuple(q[idx].tolist()), Tt[idx])
            valid[idx] = pos < tol and rot < tol
            q[idx] = (np.asarray(qi) + np.pi) % (2 * np.pi) - np.pi
    return q, valid, np.where(valid, flags, 0)
