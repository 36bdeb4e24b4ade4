"""The kinematic chain of an arm, ``T(q) = O1 Rz(θ1) O2 Rz(θ2) … O6 Rz(θ6) O7``, in either of its two
models (:class:`KinematicModel`; see :mod:`services.kinematics.analytic`), with its forward kinematics and
the constants of its closed-form inverse (:attr:`Chain.closed_form`; solved in
:mod:`services.kinematics.closed_form` and :mod:`services.kinematics.closed_form_batch`).
"""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from services.common.errors import ConfigurationError
from services.kinematics.robot_models import RobotSpec

Array = np.ndarray


class KinematicModel(enum.Enum):
    """Which model of the arm to solve on (see :mod:`services.kinematics.analytic`)."""

    DH = "dh"  # the idealised DH table: the simulated cell's model
    URDF = "urdf"  # config/robots/<name>.urdf: the robot's own model


class ClosedForm(NamedTuple):
    """Constants of the closed form of a :class:`Chain` (names as in the docstring of
    :mod:`services.kinematics.closed_form`)."""

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
    def closed_form(self) -> ClosedForm | None:
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
        t1 = og[0][:3, 3]
        return ClosedForm(
            float(t1[0]),
            float(t1[1]),
            float(t1[2]),
            tuple(float(v) for v in R2.ravel()),
            float(t2[0]),
            float(t2[1]),
            float(t2[2]),
            float(u[0]),
            float(u[1]),
            float(u[2]),
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
            _triple(tau5),
            _triple(tau6),
            r7,
            _triple(og[6][:3, 3]),
            tuple(float(v) for v in offsets),
        )


def _triple(v: Array | tuple[float, ...]) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


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


def rz(theta: Array) -> Array:
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
        T = T @ rz(theta[..., i]) @ ch.origins[i + 1]
    return T
