"""Force closure and the Ferrari–Canny ε metric (LLD §10.3, done properly).

Each point contact pushes with a unit normal force and friction inside the Coulomb cone of
half-angle atan(μ), approximated by ``cone_edges`` edge forces ``n + μ(cos θ t1 + sin θ t2)``.
A soft-finger contact (a pad pressing on a patch) also resists twisting about its normal, up to
``γ·f_n``: two extra generators carry the pure normal force with torsion ±γ. Every generator
becomes a wrench ``(f, (p − o) × f / λ)`` about the object origin ``o``; dividing the torque by a
characteristic length λ makes forces and torques commensurable (ε is unit-free in force units).

The grasp wrench space (GWS) is the convex hull of all generators (the L1 / "sum of normal forces
≤ 1" variant), built with qhull. Force closure holds iff the origin lies strictly inside it; the
Ferrari–Canny ε is then the radius of the largest origin-centred ball inside the hull: the
smallest distance from the origin to a facet hyperplane. Outside (or a hull that is not
6-dimensional, e.g. two hard point contacts that cannot resist twisting about their line) ε = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import ConvexHull, QhullError

from services.common.errors import InvalidInputError

Array = np.ndarray

INTERIOR_TOL = 1e-9  # a facet closer to the origin than this counts as the origin on the boundary


@dataclass(frozen=True)
class ContactModel:
    """Friction and contact type shared by every contact of a grasp."""

    friction_coefficient: float = 0.5
    cone_edges: int = 8
    torsional_friction_m: float = 0.0  # γ: 0 = hard point contacts

    def __post_init__(self) -> None:
        if not (math.isfinite(self.friction_coefficient) and self.friction_coefficient > 0):
            raise InvalidInputError(f"friction coefficient must be positive, got {self.friction_coefficient}")
        if not 3 <= self.cone_edges <= 64:
            raise InvalidInputError(f"friction cone needs 3 to 64 edges, got {self.cone_edges}")
        if not (math.isfinite(self.torsional_friction_m) and self.torsional_friction_m >= 0):
            raise InvalidInputError(f"torsional friction must be >= 0 m, got {self.torsional_friction_m}")


@dataclass(frozen=True)
class ForceClosureResult:
    force_closure: bool
    epsilon: float  # Ferrari–Canny, in units of one unit normal force; 0 without force closure
    n_wrenches: int
    reason: str = ""


def tangent_basis(normals: Array) -> tuple[Array, Array]:
    """Two unit tangents per unit normal (rows), right-handed with it."""
    n = np.asarray(normals, dtype=float)
    # pick the world axis least aligned with each normal to build the first tangent
    helper = np.zeros_like(n)
    helper[np.arange(n.shape[0]), np.argmin(np.abs(n), axis=1)] = 1.0
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    return t1, t2


def friction_cone_edges(normals: ArrayLike, mu: float, n_edges: int) -> Array:
    """Edge forces of the linearised friction cones: (n_contacts, n_edges, 3), unit normal part."""
    n = np.asarray(normals, dtype=float)
    t1, t2 = tangent_basis(n)
    theta = np.arange(n_edges) * (2 * np.pi / n_edges)
    return (
        n[:, None, :]
        + mu * np.cos(theta)[None, :, None] * t1[:, None, :]
        + mu * np.sin(theta)[None, :, None] * t2[:, None, :]
    )


def contact_wrenches(
    points: ArrayLike,
    normals: ArrayLike,
    model: ContactModel,
    torque_scale_m: float,
    origin: ArrayLike = (0.0, 0.0, 0.0),
) -> Array:
    """Primitive wrenches (K, 6) = (force, torque / λ) of every contact's cone generators.

    ``normals`` point into the object (the direction the finger pushes).
    """
    p, n = _check_contacts(points, normals)
    if not (math.isfinite(torque_scale_m) and torque_scale_m > 0):
        raise InvalidInputError(
            f"torque scale (characteristic length) must be positive, got {torque_scale_m}"
        )
    r = p - np.asarray(origin, dtype=float)
    edges = friction_cone_edges(n, model.friction_coefficient, model.cone_edges)  # (c, e, 3)
    torques = np.cross(r[:, None, :], edges)
    w = [np.concatenate([edges, torques / torque_scale_m], axis=-1).reshape(-1, 6)]
    if model.torsional_friction_m > 0:
        base_t = np.cross(r, n)
        for sign in (1.0, -1.0):
            tw = base_t + sign * model.torsional_friction_m * n
            w.append(np.concatenate([n, tw / torque_scale_m], axis=-1))
    return np.vstack(w)


def ferrari_canny(wrenches: ArrayLike) -> float:
    """ε of the convex hull of ``wrenches`` (K, 6): 0 when the origin is not strictly inside."""
    W = np.asarray(wrenches, dtype=float)
    if W.ndim != 2 or W.shape[1] != 6:
        raise InvalidInputError(f"wrenches must be (K, 6), got shape {W.shape}")
    if not np.all(np.isfinite(W)):
        raise InvalidInputError("wrenches contain NaN or infinite values")
    if W.shape[0] < 7 or np.linalg.matrix_rank(W - W.mean(axis=0), tol=1e-9) < 6:
        return 0.0  # a hull of fewer than 7 points, or a flat one, has no interior
    try:
        hull = ConvexHull(W)
    except QhullError:
        return 0.0
    # facet equations: unit normal · x + offset <= 0 inside; distance from the origin = -offset
    dist = -hull.equations[:, -1]
    eps = float(dist.min())
    return eps if eps > INTERIOR_TOL else 0.0


def evaluate_force_closure(
    points: ArrayLike,
    normals: ArrayLike,
    model: ContactModel,
    torque_scale_m: float,
    origin: ArrayLike = (0.0, 0.0, 0.0),
) -> ForceClosureResult:
    """Force closure test and ε for contacts (points, inward normals) on an object."""
    W = contact_wrenches(points, normals, model, torque_scale_m, origin)
    eps = ferrari_canny(W)
    if eps > 0:
        return ForceClosureResult(True, eps, W.shape[0])
    return ForceClosureResult(
        False, 0.0, W.shape[0], "the origin is not strictly inside the grasp wrench space"
    )


def _check_contacts(points: ArrayLike, normals: ArrayLike) -> tuple[Array, Array]:
    p = np.asarray(points, dtype=float)
    n = np.asarray(normals, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape != n.shape or p.shape[0] == 0:
        raise InvalidInputError(
            f"contacts need matching (N, 3) points and normals, got {p.shape} and {n.shape}"
        )
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(n))):
        raise InvalidInputError("contact points or normals contain NaN or infinite values")
    norms = np.linalg.norm(n, axis=1)
    if np.any(norms < 1e-9):
        raise InvalidInputError(f"contact normals must be non-zero, got norms {norms.tolist()}")
    return p, n / norms[:, None]
