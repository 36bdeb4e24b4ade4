"""Closed-form inverse kinematics of the UR-structure arms (Nova5, UR5e, UR3), exact on the arm's model.

Two models of each arm (:class:`KinematicModel`):

- ``URDF``: the robot's own model, ``config/robots/<name>.urdf`` — what pinocchio, the planner and
  the collision checks evaluate. For the URs its frames are the DH frames; for the Nova5 it is
  Dobot's joint table verbatim, which is no ideal DH chain: its rounded 1.5708 rad leaves J5 and J6
  3.7 µrad off square, J2 0.23 µrad off square to J1, and link offsets up to 0.5 µm off the nominal
  ones (6.3 µm at the flange).
- ``DH``: the idealised table of :mod:`~services.kinematics.robot_models`, ``T_i = Rz(θ_i) Tz(d_i)
  Tx(a_i) Rx(α_i)`` with θ_i = q_i + offset_i. The simulated cell is built on it (the simulated
  controller and the MuJoCo twin), so the module-level functions default to it and
  :func:`fk` / :func:`fk_all` evaluate it; :class:`services.kinematics.model.Kinematics` solves on
  the URDF.

Both are a :class:`Chain`, ``T(q) = O1 Rz(θ1) O2 Rz(θ2) … O6 Rz(θ6) O7``, and the inverse is solved
in closed form on that chain itself — exactly, with no idealised table to refine afterwards. It
needs (:attr:`Chain.closed_form` checks it; true of both models of all three arms): O1 turns about z
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
:class:`Singularity` flag, and two of them closer than :data:`DUPLICATE_RAD` are returned once.

UR frames: the base here (``base_link`` in our URDFs) is UR's controller ``base`` frame (URScript
poses), i.e. ROS ur_description's ``base_link`` turned 180° about z.
"""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from services.common.errors import ConfigurationError, IKFailureError, InvalidInputError
from services.kinematics.robot_models import RobotSpec

Array = np.ndarray

# A solution whose branch pair is this close to meeting (the sine of the half-angle between the
# pair: ψ for the shoulder, θ3 for the elbow, the J6-to-J2 axis angle for the wrist) is flagged.
SINGULAR_RAD = 1e-6
# A cosine up to this far beyond ±1 is clipped (the pose is at, or a hair beyond, a boundary) and
# the solution polished and checked on the chain; farther, the branch does not exist.
CLIP_SLACK = 1e-6
# Beyond ±1 by no more than this is rounding: the clipped solution is exact without a check.
_ROUNDING = 1e-12
# Two solutions flagged at the same singularity and closer than this in every joint are one solution
# (both exact): the branches that meet there, apart by rounding only (θ3 = ±acos(−1 + 1e-16) ≈ ±1e-8).
DUPLICATE_RAD = 1e-6
_POLISH_STEPS = 12  # Gauss–Newton steps for a clipped solution (quadratic: 3-4 suffice off a singularity)
_PI = math.pi
_TWO_PI = 2.0 * math.pi


class KinematicModel(enum.Enum):
    """Which model of the arm to solve on (see the module docstring)."""

    DH = "dh"  # the idealised DH table: the simulated cell's model
    URDF = "urdf"  # config/robots/<name>.urdf: the robot's own model


class Singularity(enum.IntFlag):
    """Where a solution sits within :data:`SINGULAR_RAD` of a singular configuration."""

    NONE = 0
    SHOULDER = 1  # the wrist on the J1 cylinder: the two shoulder branches meet
    ELBOW = 2  # arm stretched or folded: the two elbow branches meet
    WRIST = 4  # J6 parallel to J2-J4: the pose does not fix θ6 (θ2-θ4 follow it); θ6 is one pick


class Branch(NamedTuple):
    """One inverse-kinematics solution: joints (rad, wrapped to [-π, π)) and its singularity flags."""

    q: tuple[float, ...]
    singular: Singularity


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


def fk(
    spec: RobotSpec,
    q: Array,
    T_flange_tool: Array | None = None,
    *,
    model: KinematicModel = KinematicModel.DH,
) -> Array:
    """Flange (or tool) pose in the base frame for joints ``q`` (..., 6) → (..., 4, 4), on ``model``."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != spec.dof:
        raise InvalidInputError(f"{spec.name} needs {spec.dof} joint values, got {q.shape[-1]}")
    if model is KinematicModel.URDF:
        T = chain_fk(chain(spec, model), q)
    else:
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


# --- the chain --------------------------------------------------------------------------------------
class _ClosedForm(NamedTuple):
    """Constants of the closed form of a :class:`Chain` (names as in the module docstring)."""

    t1x: float  # O1 = Tr(t1) (its turn about z is in o1)
    t1y: float
    t1z: float
    r2: tuple[float, ...]  # O2 rotation, row-major
    t2x: float
    t2y: float
    t2z: float
    ux: float  # u = R2 e_z: the J2-J4 axis in the J1 frame at θ1 = 0
    uy: float
    uz: float
    delta: float  # n·(p_T1 − μ z_T1) = δ
    mu: float
    l3: float  # the planar links: length and direction of O3's and O4's offsets in their plane
    beta3: float
    l4: float
    beta4: float
    h: float  # their offset along the J2-J4 axis
    ca5: float  # O5 = Tr(t5) Rx(α5), O6 = Tr(t6) Rx(α6)
    sa5: float
    ca6: float
    sa6: float
    tau5: tuple[float, float, float]  # Rx(−α5) t5
    tau6: tuple[float, float, float]  # Rx(−α6) t6
    r7: tuple[float, ...] | None  # O7 rotation, row-major; None when it is the identity
    t7: tuple[float, float, float]
    offsets: tuple[float, ...]  # o1..o6 with the z turns of O1, O3..O6 folded in


_STRUCTURE_TOL = 1e-12  # a structural zero (a rotation entry, the J5→J6 x offset) may be this far off


def _about_z(R: Array) -> float | None:
    """γ when R = Rz(γ) (to _STRUCTURE_TOL), else None."""
    if max(abs(R[0, 2]), abs(R[1, 2]), abs(R[2, 0]), abs(R[2, 1]), abs(R[2, 2] - 1.0)) > _STRUCTURE_TOL:
        return None
    return math.atan2(R[1, 0], R[0, 0])


def _x_then_z(R: Array) -> tuple[float, float] | None:
    """(α, γ) when R = Rx(α) Rz(γ) (to _STRUCTURE_TOL), else None."""
    gamma = math.atan2(-R[0, 1], R[0, 0])
    alpha = math.atan2(-R[1, 2], R[2, 2])
    ca, sa, cg, sg = math.cos(alpha), math.sin(alpha), math.cos(gamma), math.sin(gamma)
    rebuilt = np.array([[cg, -sg, 0.0], [ca * sg, ca * cg, -sa], [sa * sg, sa * cg, ca]])
    return (alpha, gamma) if float(np.abs(rebuilt - R).max()) <= _STRUCTURE_TOL else None


@dataclass(frozen=True, eq=False)
class Chain:
    """``T(q) = O1 Rz(q1 + o1) O2 Rz(q2 + o2) … O6 Rz(q6 + o6) O7``: six revolute joints about z
    between fixed transforms ``origins`` = (O1, …, O7), each 4×4; O7 is the flange (and tool)."""

    name: str
    origins: tuple[Array, ...]
    offsets: tuple[float, ...]

    def with_tool(self, T_flange_tool: Array) -> Chain:
        """The same arm ending at a tool frame instead of the flange."""
        og = self.origins
        return Chain(
            f"{self.name}+tool", (*og[:6], og[6] @ np.asarray(T_flange_tool, dtype=float)), self.offsets
        )

    @functools.cached_property
    def closed_form(self) -> _ClosedForm | None:
        """The closed-form constants, or None when the chain lacks the structure it needs."""
        og = self.origins
        gammas = [_about_z(og[0][:3, :3]), None, _about_z(og[2][:3, :3]), _about_z(og[3][:3, :3])]
        wrist5, wrist6 = _x_then_z(og[4][:3, :3]), _x_then_z(og[5][:3, :3])
        if gammas[0] is None or gammas[2] is None or gammas[3] is None or wrist5 is None or wrist6 is None:
            return None
        (a5, g5), (a6, g6) = wrist5, wrist6
        sa5, ca5, sa6, ca6 = math.sin(a5), math.cos(a5), math.sin(a6), math.cos(a6)
        t2, t3, t4, t5, t6 = (og[k][:3, 3] for k in range(1, 6))
        # the J5→J6 offset must lie in the plane of J6's axis g = Rx(α6) e_z and e_z: t6 = μ g + ν e_z
        if abs(t6[0]) > _STRUCTURE_TOL or abs(sa5) < 1e-3 or abs(sa6) < 1e-3:
            return None
        mu = -float(t6[1]) / sa6
        nu = float(t6[2]) - mu * ca6
        R2 = og[1][:3, :3]
        u = R2[:, 2]
        h = float(t3[2] + t4[2])
        delta = float(u @ t2) + h + float(t5[2]) + nu * ca5
        l3, l4 = math.hypot(t3[0], t3[1]), math.hypot(t4[0], t4[1])
        if l3 < 1e-6 or l4 < 1e-6:
            return None
        tau5 = (float(t5[0]), ca5 * t5[1] + sa5 * t5[2], -sa5 * t5[1] + ca5 * t5[2])
        tau6 = (float(t6[0]), ca6 * t6[1] + sa6 * t6[2], -sa6 * t6[1] + ca6 * t6[2])
        R7 = og[6][:3, :3]
        r7 = None if np.array_equal(R7, np.eye(3)) else tuple(float(v) for v in R7.ravel())
        o = self.offsets
        offsets = (o[0] + gammas[0], o[1], o[2] + gammas[2], o[3] + gammas[3], o[4] + g5, o[5] + g6)
        return _ClosedForm(
            *(float(v) for v in og[0][:3, 3]),
            tuple(float(v) for v in R2.ravel()),
            *(float(v) for v in t2),
            *(float(v) for v in u),
            delta,
            mu,
            l3,
            math.atan2(t3[1], t3[0]),
            l4,
            math.atan2(t4[1], t4[0]),
            h,
            ca5,
            sa5,
            ca6,
            sa6,
            tuple(float(v) for v in tau5),  # type: ignore[arg-type]
            tuple(float(v) for v in tau6),  # type: ignore[arg-type]
            r7,
            tuple(float(v) for v in og[6][:3, 3]),  # type: ignore[arg-type]
            tuple(float(v) for v in offsets),
        )


def _translation_rx(d: float, a: float, alpha: float) -> Array:
    """The fixed part of a DH row, Tz(d) Tx(a) Rx(alpha)."""
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array([[1.0, 0.0, 0.0, a], [0.0, ca, -sa, 0.0], [0.0, sa, ca, d], [0.0, 0.0, 0.0, 1.0]])


def _build_chain(spec: RobotSpec, model: KinematicModel) -> Chain:
    if spec.dof != 6:
        raise ConfigurationError(f"{spec.name}: the closed form needs 6 joints, not {spec.dof}")
    if model is KinematicModel.DH:
        rows = [_translation_rx(spec.d[i], spec.a[i], spec.alpha[i]) for i in range(6)]
        return Chain(f"{spec.name} (DH)", (np.eye(4), *rows), tuple(float(v) for v in spec.theta_offset))
    from services.kinematics.urdf import arm_joints  # urdf imports settings; only the URDF model needs it

    if spec.name not in ("nova5", "ur5e", "ur3"):
        raise ConfigurationError(f"{spec.name} has no URDF joint table of ours")
    joints = arm_joints(spec)
    moving = [j for j in joints if j.axis is not None]
    if len(moving) != 6 or any(
        j.axis[0] != 0.0 or j.axis[1] != 0.0 or j.axis[2] <= 0.0 for j in moving if j.axis is not None
    ):
        raise ConfigurationError(f"{spec.name}: the closed form needs six joints about +z")
    flange = [j.T_parent_child() for j in joints if j.axis is None] or [np.eye(4)]
    return Chain(f"{spec.name} (URDF)", (*(j.T_parent_child() for j in moving), flange[0]), (0.0,) * 6)


_CHAINS: dict[tuple[int, KinematicModel], tuple[RobotSpec, Chain]] = {}


def chain(spec: RobotSpec, model: KinematicModel = KinematicModel.DH) -> Chain:
    """The kinematic chain of ``spec`` in ``model`` (cached per spec object)."""
    hit = _CHAINS.get((id(spec), model))
    if hit is not None and hit[0] is spec:
        return hit[1]
    if len(_CHAINS) > 32:  # specs are few; bound the cache anyway
        _CHAINS.clear()
    built = _build_chain(spec, model)
    _CHAINS[(id(spec), model)] = (spec, built)
    return built


def _rz(theta: Array) -> Array:
    c, s = np.cos(theta), np.sin(theta)
    T = np.zeros((*np.shape(theta), 4, 4))
    T[..., 0, 0] = c
    T[..., 0, 1] = -s
    T[..., 1, 0] = s
    T[..., 1, 1] = c
    T[..., 2, 2] = 1.0
    T[..., 3, 3] = 1.0
    return T


def chain_fk(ch: Chain, q: Array) -> Array:
    """End pose of the chain (flange, or tool) for joints ``q`` (..., 6) → (..., 4, 4)."""
    theta = np.asarray(q, dtype=float) + np.asarray(ch.offsets)
    T = np.broadcast_to(ch.origins[0], (*theta.shape[:-1], 4, 4))
    for i in range(6):
        T = T @ _rz(theta[..., i]) @ ch.origins[i + 1]
    return T


# --- the closed form, one pose in plain floats (the hot path) ---------------------------------------
Solution = tuple[
    float, tuple[float, ...], int, bool
]  # (distance to the seed, joints, singular bits, clipped)


def _closed_form(
    cf: _ClosedForm,
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
        clipped1 = abs(c) > 1.0 + _ROUNDING
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
            clipped5 = clipped5 or abs(c5) > 1.0 + _ROUNDING
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
                clipped = clipped or abs(c3) > 1.0 + _ROUNDING
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
        F = F @ _rz(q[i] + ch.offsets[i])
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


def _polish(ch: Chain, q0: tuple[float, ...], T: Array) -> tuple[tuple[float, ...], float, float]:
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
    q, pos, rot = _polish(ch, sol[1], T)
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


def _solve(
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
    sols = _solve(ch, T, tol, seed_l, lower, upper)
    if not sols:
        return np.zeros((0, 6))
    sols.sort()  # by distance first (ties: by joints, deterministic)
    return np.array([s[1] for s in sols])


# --- the closed form, vectorised over poses ----------------------------------------------------------
def _clip(c: Array) -> tuple[Array, Array, Array]:
    """(clipped cosine, exists: within CLIP_SLACK of [-1, 1], clipped beyond rounding)."""
    a = np.abs(c)
    return np.clip(c, -1.0, 1.0), a <= 1.0 + CLIP_SLACK, a > 1.0 + _ROUNDING


def _closed_form_batch(cf: _ClosedForm, T: Array) -> tuple[Array, Array, Array, Array]:
    """All 8 branches of every pose T (..., 4, 4): joints (..., 8, 6) unwrapped, exists, clipped,
    singularity bits (..., 8). The same steps as :func:`_closed_form`."""
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


def _chain_ik_all(ch: Chain, T_base_flange: Array, tol: float) -> tuple[Array, Array, Array]:
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
            qi, pos, rot = _polish(ch, tuple(q[idx].tolist()), Tt[idx])
            valid[idx] = pos < tol and rot < tol
            q[idx] = (np.asarray(qi) + np.pi) % (2 * np.pi) - np.pi
    return q, valid, np.where(valid, flags, 0)


# --- public entry points -------------------------------------------------------------------------------
def ik_all(
    spec: RobotSpec, T_base_flange: Array, *, tol: float = 1e-6, model: KinematicModel = KinematicModel.DH
) -> tuple[Array, Array]:
    """All closed-form solutions for a batch of flange poses.

    ``T_base_flange``: (..., 4, 4). Returns ``(q, valid)`` with q of shape (..., 8, 6) in radians
    wrapped to [-π, π) and ``valid`` (..., 8) true where the branch exists on ``model`` (exactly, or
    for a pose at a boundary: within ``tol``, m / rad). Branch b is the same choice (shoulder, wrist,
    elbow) in every pose; at a singularity two branches may hold the same solution. Joint limits are
    not applied here (see :func:`solutions_within_limits`).
    """
    q, valid, _ = _chain_ik_all(chain(spec, model), T_base_flange, tol)
    return q, valid


def ik_all_flagged(
    spec: RobotSpec, T_base_flange: Array, *, tol: float = 1e-6, model: KinematicModel = KinematicModel.DH
) -> tuple[Array, Array, Array]:
    """:func:`ik_all` plus the :class:`Singularity` bits of every branch (..., 8) (0 where invalid)."""
    return _chain_ik_all(chain(spec, model), T_base_flange, tol)


def ik_branches(
    spec: RobotSpec, T_base_flange: Array, tol: float = 1e-6, *, model: KinematicModel = KinematicModel.DH
) -> list[Branch]:
    """Every solution for one flange pose, once each, with its singularity flags, in branch order."""
    return [Branch(q, Singularity(f)) for _, q, f, _ in _solve(chain(spec, model), T_base_flange, tol)]


def ik_solutions(
    spec: RobotSpec, T_base_flange: Array, tol: float = 1e-6, *, model: KinematicModel = KinematicModel.DH
) -> list[tuple[float, ...]]:
    """All closed-form solutions for one flange pose; plain-float fast path.

    The branches of :func:`ik_all` (angles wrapped to [-π, π), joint limits not applied), only the
    valid ones, each once (at a singularity two branches can be one solution), as 6-tuples.
    """
    return [q for _, q, _, _ in _solve(chain(spec, model), T_base_flange, tol)]


def solutions_within_limits(
    spec: RobotSpec,
    T_base_flange: Array,
    seed: Array | None = None,
    *,
    model: KinematicModel = KinematicModel.DH,
) -> Array:
    """Valid, in-limit solutions for one pose, each moved to the turn nearest ``seed``,
    sorted by distance to the seed (weighted max-norm). Shape (k, 6), k ≤ 8."""
    lower, upper = _limits(spec)
    return solve_within_limits(chain(spec, model), T_base_flange, seed, lower, upper)


def _limits(spec: RobotSpec) -> tuple[list[float], list[float]]:
    hit = _LIMITS.get(id(spec))
    if hit is None or hit[0] is not spec:
        if len(_LIMITS) > 32:
            _LIMITS.clear()
        hit = (spec, [float(v) for v in spec.lower], [float(v) for v in spec.upper])
        _LIMITS[id(spec)] = hit
    return hit[1], hit[2]


_LIMITS: dict[int, tuple[RobotSpec, list[float], list[float]]] = {}


def solve_nearest(
    spec: RobotSpec, T_base_flange: Array, seed: Array, *, model: KinematicModel = KinematicModel.DH
) -> Array:
    """The in-limit solution nearest the seed; IKFailureError (with the pose) when none."""
    sols = solutions_within_limits(spec, T_base_flange, seed, model=model)
    if sols.shape[0] == 0:
        p = np.asarray(T_base_flange)[:3, 3]
        raise IKFailureError(
            f"{spec.name}: no inverse-kinematics solution within joint limits for the flange at "
            f"({p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}) m"
        )
    return sols[0]
