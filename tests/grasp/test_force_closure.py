"""Force closure and the Ferrari–Canny ε (LLD §10.3): friction cones, wrench hull, ε."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import linprog

from services.common.errors import InvalidInputError
from services.grasp.force_closure import (
    ContactModel,
    contact_wrenches,
    evaluate_force_closure,
    ferrari_canny,
    friction_cone_edges,
)

HARD = ContactModel(friction_coefficient=0.5, cone_edges=8, torsional_friction_m=0.0)


def pads(half_width: float, normal_tilt_rad: float, half_len: float = 0.011) -> tuple[np.ndarray, np.ndarray]:
    """Two flat pads squeezing along y, each a line contact of 2 points along x.

    Each pad's normal is tilted by ``normal_tilt_rad`` toward +z: a wedge (V shape) whose faces
    are ``2 · tilt`` from parallel; the connecting line lies inside both friction cones iff
    tilt < atan(μ).
    """
    c, s = math.cos(normal_tilt_rad), math.sin(normal_tilt_rad)
    pts, nrm = [], []
    for side in (1.0, -1.0):
        for x in (-half_len, half_len):
            pts.append([x, side * half_width, 0.0])
            nrm.append([0.0, -side * c, s])
    return np.array(pts), np.array(nrm)


@pytest.mark.parametrize("mu", [0.3, 0.5, 1.0])
def test_antipodal_pair_inside_the_friction_cone_is_force_closure(mu: float) -> None:
    model = ContactModel(mu, 8, 0.0)
    half_angle = math.atan(mu)
    pts, nrm = pads(0.011, 0.6 * half_angle)
    res = evaluate_force_closure(pts, nrm, model, torque_scale_m=0.1)
    assert res.force_closure and res.epsilon > 0


@pytest.mark.parametrize("mu", [0.3, 0.5, 1.0])
def test_contacts_outside_the_friction_cone_are_not_force_closure(mu: float) -> None:
    model = ContactModel(mu, 8, 0.0)
    pts, nrm = pads(0.011, 1.3 * math.atan(mu))  # the object would squirt out of the V
    res = evaluate_force_closure(pts, nrm, model, torque_scale_m=0.1)
    assert not res.force_closure and res.epsilon == 0.0
    assert "origin" in res.reason


def test_two_hard_point_contacts_cannot_resist_twisting_but_soft_fingers_can() -> None:
    pts = np.array([[0.0, 0.02, 0.0], [0.0, -0.02, 0.0]])
    nrm = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    assert not evaluate_force_closure(pts, nrm, HARD, 0.05).force_closure
    soft = ContactModel(0.5, 8, torsional_friction_m=0.005)
    res = evaluate_force_closure(pts, nrm, soft, 0.05)
    assert res.force_closure and res.epsilon > 0


def test_line_contacts_along_a_cylinder_give_3d_force_closure() -> None:
    pts, nrm = pads(0.011, 0.0)
    assert evaluate_force_closure(pts, nrm, HARD, 0.1).force_closure


def test_one_sided_contacts_are_not_force_closure() -> None:
    pts, nrm = pads(0.011, 0.0)
    one = evaluate_force_closure(pts[:2], nrm[:2], ContactModel(0.8, 8, 0.01), 0.1)
    assert not one.force_closure and one.epsilon == 0.0


def test_epsilon_grows_with_friction() -> None:
    pts, nrm = pads(0.011, 0.0)
    eps = [evaluate_force_closure(pts, nrm, ContactModel(mu, 8, 0.0), 0.1).epsilon for mu in (0.2, 0.5, 1.0)]
    assert eps[0] < eps[1] < eps[2]


def test_epsilon_is_the_radius_of_the_largest_ball_inside_the_hull() -> None:
    """Independent check by linear programming: ε·d is in the hull for every direction d (up to ε),
    and (ε + δ)·d* leaves it along the facet normal d* that realises ε."""
    pts, nrm = pads(0.011, 0.2)
    W = contact_wrenches(pts, nrm, ContactModel(0.5, 6, 0.004), 0.1)
    eps = ferrari_canny(W)
    assert eps > 0

    def in_hull(x: np.ndarray) -> bool:
        k = W.shape[0]
        A_eq = np.vstack([W.T, np.ones((1, k))])
        b_eq = np.concatenate([x, [1.0]])
        return linprog(np.zeros(k), A_eq=A_eq, b_eq=b_eq, bounds=(0, None), method="highs").status == 0

    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(40, 6))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    assert all(in_hull(0.999 * eps * d) for d in dirs)
    from scipy.spatial import ConvexHull

    hull = ConvexHull(W)
    d_star = hull.equations[np.argmax(hull.equations[:, -1]), :6]
    assert in_hull(0.999 * eps * d_star)
    assert not in_hull(1.01 * eps * d_star)


def test_epsilon_is_scale_invariant_with_the_torque_scale() -> None:
    pts, nrm = pads(0.011, 0.1)
    model = ContactModel(0.5, 8, 0.0)
    e1 = evaluate_force_closure(pts, nrm, model, 0.1).epsilon
    e2 = evaluate_force_closure(pts * 3.0, nrm, model, 0.3).epsilon  # 3x larger object, same shape
    assert e1 == pytest.approx(e2, rel=1e-6)


def test_friction_cone_edges_lie_on_the_cone() -> None:
    n = np.array([[0.0, 0.0, 1.0], [1.0, 1.0, 0.0]]) / np.array([[1.0], [math.sqrt(2)]])
    edges = friction_cone_edges(n, 0.4, 6)
    assert edges.shape == (2, 6, 3)
    for c in range(2):
        normal_part = edges[c] @ n[c]
        tangential = np.linalg.norm(edges[c] - normal_part[:, None] * n[c], axis=1)
        assert np.allclose(normal_part, 1.0) and np.allclose(tangential, 0.4)


@pytest.mark.parametrize(
    ("points", "normals"),
    [
        (np.array([[0.0, 0.0, np.nan]]), np.array([[0.0, 0.0, 1.0]])),
        (np.zeros((2, 3)), np.zeros((3, 3))),
        (np.zeros((1, 3)), np.zeros((1, 3))),
    ],
)
def test_bad_contacts_raise_invalid_input(points: np.ndarray, normals: np.ndarray) -> None:
    with pytest.raises(InvalidInputError):
        evaluate_force_closure(points, normals, HARD, 0.1)


def test_bad_contact_model_raises_invalid_input() -> None:
    with pytest.raises(InvalidInputError, match="friction"):
        ContactModel(friction_coefficient=-1.0)
    with pytest.raises(InvalidInputError, match="edges"):
        ContactModel(cone_edges=2)
