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

Both are a :class:`~services.kinematics.chain.Chain`, ``T(q) = O1 Rz(θ1) O2 Rz(θ2) … O6 Rz(θ6) O7``
(:mod:`services.kinematics.chain`), and the inverse is solved in closed form on that chain itself —
exactly, with no idealised table to refine afterwards: :mod:`services.kinematics.closed_form` for one
pose (its docstring derives it), :mod:`services.kinematics.closed_form_batch` for many. This module is
the entry point callers use.

Up to 8 solutions per pose, exact to rounding; a pose at a boundary (a cosine clipped) is polished on
the chain and kept only if it reproduces the pose within ``tol``. Solutions within :data:`SINGULAR_RAD`
of the shoulder, elbow or wrist singularity carry a :class:`Singularity` flag, and two of them closer
than :data:`DUPLICATE_RAD` are returned once.

UR frames: the base here (``base_link`` in our URDFs) is UR's controller ``base`` frame (URScript
poses), i.e. ROS ur_description's ``base_link`` turned 180° about z.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import numpy as np

from services.common.errors import IKFailureError, InvalidInputError
from services.kinematics.chain import Chain, KinematicModel, chain, chain_fk
from services.kinematics.closed_form import DUPLICATE_RAD, SINGULAR_RAD, solve, solve_within_limits
from services.kinematics.closed_form_batch import chain_ik_all
from services.kinematics.robot_models import RobotSpec

Array = np.ndarray

# the public API; chain, closed form and batch solver live in their own modules, re-exported here
__all__ = [
    "DUPLICATE_RAD",
    "SINGULAR_RAD",
    "Branch",
    "Chain",
    "KinematicModel",
    "Singularity",
    "chain",
    "chain_fk",
    "dh_matrices",
    "fk",
    "fk_all",
    "ik_all",
    "ik_all_flagged",
    "ik_branches",
    "ik_solutions",
    "manipulability",
    "nearest_equivalent",
    "solutions_within_limits",
    "solve_nearest",
    "solve_within_limits",
]


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
    q, valid, _ = chain_ik_all(chain(spec, model), T_base_flange, tol)
    return q, valid


def ik_all_flagged(
    spec: RobotSpec, T_base_flange: Array, *, tol: float = 1e-6, model: KinematicModel = KinematicModel.DH
) -> tuple[Array, Array, Array]:
    """:func:`ik_all` plus the :class:`Singularity` bits of every branch (..., 8) (0 where invalid)."""
    return chain_ik_all(chain(spec, model), T_base_flange, tol)


def ik_branches(
    spec: RobotSpec, T_base_flange: Array, tol: float = 1e-6, *, model: KinematicModel = KinematicModel.DH
) -> list[Branch]:
    """Every solution for one flange pose, once each, with its singularity flags, in branch order."""
    return [Branch(q, Singularity(f)) for _, q, f, _ in solve(chain(spec, model), T_base_flange, tol)]


def ik_solutions(
    spec: RobotSpec, T_base_flange: Array, tol: float = 1e-6, *, model: KinematicModel = KinematicModel.DH
) -> list[tuple[float, ...]]:
    """All closed-form solutions for one flange pose; plain-float fast path.

    The branches of :func:`ik_all` (angles wrapped to [-π, π), joint limits not applied), only the
    valid ones, each once (at a singularity two branches can be one solution), as 6-tuples.
    """
    return [q for _, q, _, _ in solve(chain(spec, model), T_base_flange, tol)]


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
