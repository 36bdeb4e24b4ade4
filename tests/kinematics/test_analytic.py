"""The closed-form IK is exact on the robot's own URDF, recovers every configuration, keeps its
branches at the boundaries (issue 11, item 10).

Exactness is judged by pinocchio on the URDF (independent of the solver); every set is seeded.
The bench (``python -m bench kinematics``) runs the same checks on 10,000 configurations per robot.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.common.errors import ConfigurationError
from services.kinematics import analytic, closed_form
from services.kinematics.analytic import KinematicModel, Singularity
from services.kinematics.chain import Chain
from services.kinematics.model import Kinematics, arm_from_urdf, load_arm
from services.kinematics.robot_models import NOVA5, UR3, UR5E, get_robot
from services.kinematics.tool import ToolGeometry
from services.kinematics.urdf import arm_joints, flange_link

ROBOTS = ("nova5", "ur5e", "ur3")
URDF = KinematicModel.URDF
EXACT = 1e-9  # m and rad
SAME_RAD = 1e-9  # random configurations come back to this
# At a boundary the pose fixes the joints less well, and the original configuration is looked for
# to what it fixes them to: on the shoulder cylinder θ1 to √ε ≈ 1e-8 and the other joints to up to
# ~100 times that (seen: 2e-6); at a straight or folded elbow θ3 to √ε and θ2, θ4 to up to 12 times
# that (UR5e: L4 / (L3 − L4)); a folded elbow with the wrist at −π often puts the wrist centre on the
# shoulder cylinder too (seen: 5e-10 m from it), and the three together leave ~4e-5 rad, with the
# pose still exact to 1e-15 m.
BOUNDARY_SAME_RAD = {"shoulder": 1e-5, "straight": 1e-5, "folded": 1e-4}


@pytest.fixture(scope="module", params=ROBOTS)
def kin(request: pytest.FixtureRequest) -> Kinematics:
    return Kinematics(load_arm(request.param))


def random_q(kin: Kinematics, rng: np.random.Generator, n: int) -> np.ndarray:
    lo = np.maximum(kin.limits.lower, -2 * np.pi)
    hi = np.minimum(kin.limits.upper, 2 * np.pi)
    return rng.uniform(lo, hi, (n, kin.dof))


def pose_error(kin: Kinematics, q: np.ndarray, T: np.ndarray) -> tuple[float, float]:
    """(position m, rotation angle rad) of pinocchio's flange pose at q against T."""
    Tq = kin.fk(q, flange_link(kin.spec))
    dR = Tq[:3, :3].T @ T[:3, :3]
    sin = 0.5 * np.linalg.norm([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]])
    return float(np.linalg.norm(Tq[:3, 3] - T[:3, 3])), math.atan2(sin, (np.trace(dR) - 1.0) / 2.0)


def joint_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Max-norm joint difference modulo full turns, along the last axis."""
    return np.max(np.abs((np.asarray(a) - b + np.pi) % (2 * np.pi) - np.pi), axis=-1)


def check_exact_and_recovered(kin: Kinematics, qs: np.ndarray, same_rad: float) -> tuple[int, list[int]]:
    """Assert every solution of every pose is exact on the URDF; return (recovered, misses)."""
    frame = flange_link(kin.spec)
    recovered, misses = 0, []
    for k, q0 in enumerate(qs):
        T = kin.fk(q0, frame)
        sols = analytic.ik_solutions(kin.spec, T, model=URDF)
        assert sols, f"{kin.spec.name}: no solution for a reachable pose, q = {q0.tolist()}"
        for q in sols:
            pos, rot = pose_error(kin, np.asarray(q), T)
            assert pos <= EXACT and rot <= EXACT, (kin.spec.name, q0.tolist(), q, pos, rot)
        if joint_gap(np.array(sols), q0).min() < same_rad:
            recovered += 1
        else:
            misses.append(k)
    return recovered, misses


# --- the chain is the URDF ---------------------------------------------------------------------------
def test_chain_fk_is_pinocchio_on_the_urdf(kin: Kinematics) -> None:
    qs = random_q(kin, np.random.default_rng(1), 200)
    T_chain = analytic.fk(kin.spec, qs, model=URDF)
    T_pin = np.array([kin.fk(q, flange_link(kin.spec)) for q in qs])
    assert np.abs(T_chain - T_pin).max() < 1e-12


def test_dh_chain_is_the_dh_table_and_nova5_urdf_is_not() -> None:
    q = random_q(Kinematics(load_arm("nova5")), np.random.default_rng(2), 200)
    for spec in (NOVA5, UR5E, UR3):
        assert np.abs(analytic.chain_fk(analytic.chain(spec), q) - analytic.fk(spec, q)).max() < 1e-13
    # the vendor's joint table is µm away from the nominal DH table: the reason for solving on it
    gap = np.linalg.norm(
        analytic.fk(NOVA5, q, model=URDF)[:, :3, 3] - analytic.fk(NOVA5, q)[:, :3, 3], axis=1
    )
    assert 1e-6 < gap.max() < 1e-5
    for spec in (UR5E, UR3):
        assert np.abs(analytic.fk(spec, q, model=URDF) - analytic.fk(spec, q)).max() < 1e-13


def test_urdf_chain_uses_the_numbers_as_written_in_the_urdf() -> None:
    urdf = load_arm("nova5").urdf
    joint2 = arm_joints(NOVA5)[1]
    assert joint2.rpy == (-1.57080287682252, 1.53586622836832, 3.14159265358979)
    assert f'rpy="{" ".join(f"{v:.15g}" for v in joint2.rpy)}"' in urdf


# --- random configurations -----------------------------------------------------------------------------
def test_every_solution_is_exact_on_the_urdf_and_the_original_is_among_them(kin: Kinematics) -> None:
    qs = random_q(kin, np.random.default_rng(7), 2000)
    recovered, misses = check_exact_and_recovered(kin, qs, SAME_RAD)
    assert recovered == len(qs), [qs[k].tolist() for k in misses[:3]]


def test_batch_agrees_with_the_single_pose_path(kin: Kinematics) -> None:
    qs = random_q(kin, np.random.default_rng(8), 500)
    frame = flange_link(kin.spec)
    Ts = np.array([kin.fk(q, frame) for q in qs])
    q_all, valid = analytic.ik_all(kin.spec, Ts, model=URDF)
    assert q_all.shape == (500, 8, 6) and valid.shape == (500, 8)
    for k in range(len(qs)):
        sols = np.array(analytic.ik_solutions(kin.spec, Ts[k], model=URDF))
        assert len(sols) == int(valid[k].sum())
        assert np.abs(joint_gap(q_all[k][valid[k]], sols)).max() < 1e-12  # the same branches, in order


def test_public_ik_is_exact_on_the_tool_pose(kin: Kinematics) -> None:
    for q0 in random_q(kin, np.random.default_rng(9), 200):
        T = kin.fk(q0)
        sols = kin.ik_analytic(T, q0)
        assert joint_gap(sols[0], q0) < SAME_RAD  # the seed itself is the nearest solution
        for q in sols:
            pos, rot = kin.pose_error(q, T)
            assert pos < EXACT and rot < 1e-7  # pose_error's acos resolves ~1e-8 rad only
            assert np.all(q >= kin.limits.lower - 1e-9) and np.all(q <= kin.limits.upper + 1e-9)


@pytest.mark.parametrize("name", ROBOTS)
def test_public_ik_with_a_turned_and_offset_tool_is_exact(name: str) -> None:
    kin = Kinematics(load_arm(name, ToolGeometry(tip_xyz=(0.01, -0.02, 0.2), tip_rpy=(0.1, -0.2, 0.3))))
    assert kin.has_analytic_ik()
    for q0 in random_q(kin, np.random.default_rng(12), 100):
        T = kin.fk(q0)
        sols = kin.ik_analytic(T, q0)
        assert joint_gap(sols[0], q0) < SAME_RAD
        assert max(kin.pose_error(q, T)[0] for q in sols) < EXACT


def test_dh_model_stays_the_default_and_exact_on_the_dh_table() -> None:
    """The simulated cell (controller, twin) is built on the DH table: its IK inverts its FK."""
    rng = np.random.default_rng(10)
    for spec in (NOVA5, UR5E, UR3):
        for q0 in random_q(Kinematics(load_arm(spec.name)), rng, 200):
            T = analytic.fk(spec, q0)
            sols = np.array(analytic.ik_solutions(spec, T))
            assert np.abs(analytic.fk(spec, sols) - T).max() < 1e-12
            assert joint_gap(sols, q0).min() < SAME_RAD


# --- the boundaries ----------------------------------------------------------------------------------------
def _shoulder_offset(spec, q: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """x of the DH wrist centre (frame-5 origin) in DH frame 1: 0 on the shoulder-singular cylinder,
    where r − d4 ≈ x² / (2 d4)."""
    theta = q + spec.theta_offset
    T = analytic.dh_matrices(spec, theta[..., 1], 1)
    for i in (2, 3, 4):
        T = T @ analytic.dh_matrices(spec, theta[..., i], i)
    return T[..., 0, 3]


def near_shoulder_cylinder(kin: Kinematics, rng: np.random.Generator, n: int, within_m: float) -> np.ndarray:
    """Configurations with the wrist centre within ``within_m`` outside the shoulder-singular
    cylinder of the DH model (for the Nova5 that is within ~1 µm of its URDF's too), both sides
    of the shoulder, a few exactly on it; found by Newton steps on q2."""
    spec = kin.spec
    q = random_q(kin, rng, 3 * n)
    x_max = math.sqrt(2 * abs(spec.d[3]) * within_m)
    target = (
        rng.choice([-1.0, 1.0], len(q))
        * x_max
        * rng.uniform(0, 1, len(q))
        * rng.choice([1, 1, 1e-3, 0], len(q))
    )
    for _ in range(20):
        f = _shoulder_offset(spec, q) - target
        h = 1e-7
        qh = q.copy()
        qh[:, 1] += h
        q[:, 1] -= f / ((_shoulder_offset(spec, qh) - _shoulder_offset(spec, q)) / h)
    ok = (np.abs(_shoulder_offset(spec, q) - target) < 1e-13) & spec.within_limits(q)
    assert ok.sum() >= n
    out = q[ok][:n]
    r_minus_d4 = np.abs(_shoulder_offset(spec, out)) ** 2 / (2 * abs(spec.d[3]))
    assert r_minus_d4.max() <= within_m
    return out


def elbow_nearly_straight(kin: Kinematics, rng: np.random.Generator, n: int) -> np.ndarray:
    """|q3| ≤ 1e-3, down to 1e-9 and exactly 0."""
    q = random_q(kin, rng, n)
    q[:, 2] = rng.uniform(-1e-3, 1e-3, n) * rng.choice([1, 1e-3, 1e-6, 0.0], n)
    return q


def folded_elbow_wrist_near_minus_pi(kin: Kinematics, rng: np.random.Generator, n: int) -> np.ndarray:
    """q3 within 1e-3 of its limit (folded: ±π for the URs) and q5 within 1e-3 of −π (but not on it)."""
    q = random_q(kin, rng, n)
    lim = kin.limits.upper[2]
    q[:, 2] = rng.choice([-1.0, 1.0], n) * (lim - rng.uniform(0, 1e-3, n) * rng.choice([1, 1e-3, 0.0], n))
    q[:, 4] = -np.pi + rng.choice([-1.0, 1.0], n) * rng.uniform(1e-6, 1e-3, n)
    return q


@pytest.mark.parametrize(
    ("boundary", "n"),
    [("shoulder", 400), ("straight", 600), ("folded", 600)],
)
def test_boundary_poses_keep_their_branches_and_are_exact(kin: Kinematics, boundary: str, n: int) -> None:
    rng = np.random.default_rng({"shoulder": 21, "straight": 22, "folded": 23}[boundary])
    if boundary == "shoulder":
        qs = near_shoulder_cylinder(kin, rng, n, within_m=1e-6)
    elif boundary == "straight":
        qs = elbow_nearly_straight(kin, rng, n)
    else:
        qs = folded_elbow_wrist_near_minus_pi(kin, rng, n)
    recovered, misses = check_exact_and_recovered(kin, qs, BOUNDARY_SAME_RAD[boundary])
    assert recovered == len(qs), [qs[k].tolist() for k in misses[:3]]


def test_ur3_folded_elbow_with_the_wrist_near_minus_pi_loses_no_branch() -> None:
    """The case that once lost 2 of 6 solutions: every branch the batch finds, the single-pose path
    finds too, and each is exact."""
    kin = Kinematics(load_arm("ur3"))
    qs = folded_elbow_wrist_near_minus_pi(kin, np.random.default_rng(24), 300)
    for q0 in qs:
        T = kin.fk(q0, "tool0")
        q_all, valid, flags = analytic.ik_all_flagged(UR3, T, model=URDF)
        sols = np.array(analytic.ik_solutions(UR3, T, model=URDF))
        assert valid.sum() >= 6  # four branches away from the fold, two (or one twice) at it
        for q in q_all[valid]:  # every batch branch is among the single-pose solutions
            assert joint_gap(sols, q).min() < BOUNDARY_SAME_RAD["folded"]
        assert joint_gap(sols, q0).min() < BOUNDARY_SAME_RAD["folded"]
        assert np.all(flags[~valid] == 0)


def test_exactly_singular_wrist_returns_exact_members_of_its_family_flagged() -> None:
    """θ5 = 0 exactly (UR: J6 along J2-J4): a one-parameter family of configurations reaches the
    pose (θ6 turns, θ2-θ4 follow); the solutions returned are exact members of it, flagged WRIST."""
    kin = Kinematics(load_arm("ur5e"))
    q0 = np.array([0.3, -1.2, 1.4, -1.0, 0.0, 0.5])
    T = kin.fk(q0, "tool0")
    branches = analytic.ik_branches(UR5E, T, model=URDF)
    wrist = [b for b in branches if b.singular & Singularity.WRIST]
    assert any(abs(b.q[0] - q0[0]) < 1e-9 and abs(b.q[4]) < 1e-9 for b in wrist)
    assert all(abs(b.q[4]) < 1e-9 for b in wrist) and len(wrist) < len(branches) <= 8
    for b in branches:
        pos, rot = pose_error(kin, np.asarray(b.q), T)
        assert pos < EXACT and rot < EXACT
    qs = np.array([b.q for b in branches])
    assert min(joint_gap(qs[i], qs[j]) for i in range(len(qs)) for j in range(i)) > 1e-6  # no twins


def test_flags_mark_the_shoulder_elbow_and_wrist() -> None:
    kin = Kinematics(load_arm("ur5e"))
    regular = np.array([0.3, -1.2, 1.4, -1.0, 1.2, 0.5])
    straight = np.array([0.3, -1.2, 0.0, -1.0, 1.2, 0.5])
    on_shoulder = near_shoulder_cylinder(kin, np.random.default_rng(3), 50, within_m=1e-14)[0]
    cases = [(regular, Singularity.NONE), (straight, Singularity.ELBOW), (on_shoulder, Singularity.SHOULDER)]
    for q0, expected in cases:
        branches = analytic.ik_branches(UR5E, kin.fk(q0, "tool0"), model=URDF)
        mine = min(branches, key=lambda b: float(joint_gap(np.array(b.q), q0)))
        assert joint_gap(np.array(mine.q), q0) < BOUNDARY_SAME_RAD["straight"]
        assert mine.singular & expected == expected and (expected or mine.singular == Singularity.NONE)
    # at a straight elbow the two elbow branches are one solution: returned once
    T = kin.fk(straight, "tool0")
    _, valid = analytic.ik_all(UR5E, T, model=URDF)
    assert len(analytic.ik_branches(UR5E, T, model=URDF)) * 2 == valid.sum()


def test_a_pose_a_hair_beyond_reach_gets_the_nearest_configuration_within_tol() -> None:
    kin = Kinematics(load_arm("ur5e"))
    stretched = np.array([0.3, -1.2, 0.0, -1.0, 1.2, 0.5])
    T = kin.fk(stretched, "tool0")
    # push the flange 1e-8 m further out along the line from the shoulder, beyond full reach
    T_out = T.copy()
    shoulder = kin.fk(stretched, "upper_arm_link")[:3, 3]
    T_out[:3, 3] += 1e-8 * (T[:3, 3] - shoulder) / np.linalg.norm(T[:3, 3] - shoulder)
    near = analytic.ik_branches(UR5E, T_out, tol=1e-6, model=URDF)
    assert near and all(b.singular & Singularity.ELBOW for b in near)
    assert all(pose_error(kin, np.asarray(b.q), T_out)[0] < 1e-6 for b in near)
    assert analytic.ik_solutions(UR5E, T_out, tol=1e-9, model=URDF) == []
    T_far = T.copy()
    T_far[:3, 3] *= 1.5
    assert analytic.ik_solutions(UR5E, T_far, model=URDF) == []


# --- structure, limits, frames --------------------------------------------------------------------------
def test_a_chain_without_the_structure_has_no_closed_form() -> None:
    ch = analytic.chain(UR5E, URDF)
    tilted = ch.origins[3].copy()  # J4 tilted off J3 by 1 mrad: J2, J3, J4 no longer parallel
    tilted[:3, :3] = [[1, 0, 0], [0, math.cos(1e-3), -math.sin(1e-3)], [0, math.sin(1e-3), math.cos(1e-3)]]
    broken = Chain("tilted", (*ch.origins[:3], tilted, *ch.origins[4:]), ch.offsets)
    assert broken.closed_form is None
    with pytest.raises(ConfigurationError, match="structure"):
        closed_form.solve(broken, np.eye(4), 1e-6)
    generic = Kinematics(arm_from_urdf(load_arm("nova5").urdf, "Link6", name="generic"))
    assert not generic.has_analytic_ik()
    # one of our names on another arm's URDF: the closed form would solve the wrong chain
    impostor = Kinematics(arm_from_urdf(load_arm("ur5e").urdf, "tool_tip", name="nova5"))
    assert not impostor.has_analytic_ik()
    assert Kinematics(load_arm("ur5e", ToolGeometry(tip_rpy=(0.1, 0.2, 0.3)))).has_analytic_ik()
    with pytest.raises(ConfigurationError, match="closed-form"):
        generic.ik_analytic(np.eye(4))


def test_ur3_wrist_3_has_one_limit_everywhere() -> None:
    arm = load_arm("ur3")
    spec = get_robot("ur3")
    assert spec.lower[5] == -2 * np.pi and spec.upper[5] == 2 * np.pi
    assert arm.model.lowerPositionLimit[5] == pytest.approx(-2 * np.pi, abs=1e-13)
    assert arm.model.upperPositionLimit[5] == pytest.approx(2 * np.pi, abs=1e-13)
    assert Kinematics(arm).limits.continuous()[5]  # two full turns: unwrapped to the seed's turn


def test_ur_base_frame_is_documented_as_the_controller_base() -> None:
    for name in ("ur5e", "ur3"):
        header = load_arm(name).urdf.split("<robot", 1)[0]
        assert "controller base frame" in header and "180 deg" in header
