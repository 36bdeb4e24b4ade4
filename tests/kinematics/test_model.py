"""FK against the spec's reference values, URDF models against the DH tables, analytic and numerical IK."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from services.common.errors import ConfigurationError, IKFailureError, InvalidInputError
from services.common.frames import make_transform, transform_to_dobot_pose
from services.kinematics import analytic
from services.kinematics.model import Kinematics, arm_from_urdf, load_arm
from services.kinematics.robot_models import NOVA5, UR3, UR5E, get_robot
from services.kinematics.tool import ToolGeometry
from services.kinematics.urdf import flange_link, link_segments, stale_urdfs

ROBOTS = ("nova5", "ur5e", "ur3")


def random_q(spec, rng, n):
    lo = np.maximum(spec.lower, -2 * np.pi)
    hi = np.minimum(spec.upper, 2 * np.pi)
    return rng.uniform(lo, hi, (n, spec.dof))


# --- forward kinematics --------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("q_deg", "pose_mm_deg"),
    [
        # spec §6.3 reference values (URDF, mm and Dobot rpy degrees)
        ((10, 20, 30, 40, 50, 60), (-468.557, -277.357, 895.660, 36.005, 18.747, -13.858)),
        ((0, 0, 90, 0, -90, 0), (-450.0, -135.0, 551.7, 180, 0, 90)),
        ((90, 0, 90, 0, -90, 0), (135.0, -450.0, 551.7, 180, 0, -180)),
    ],
)
def test_nova5_fk_matches_spec_reference(q_deg, pose_mm_deg):
    T = analytic.fk(NOVA5, np.deg2rad(q_deg))
    pose = transform_to_dobot_pose(T)
    assert np.allclose(pose[:3], pose_mm_deg[:3], atol=0.06)  # the spec rounds 551.7 to 0.1 mm
    # angles compared as rotations (±180° are the same yaw)
    expected = make_transform(
        __import__("services.common.frames", fromlist=["rpy_deg_to_matrix"]).rpy_deg_to_matrix(
            pose_mm_deg[3:]
        ),
        np.zeros(3),
    )
    assert np.allclose(T[:3, :3], expected[:3, :3], atol=1e-3)


def test_nova5_fk_reference_within_a_hundredth_of_a_millimetre():
    T = analytic.fk(NOVA5, np.deg2rad([10, 20, 30, 40, 50, 60]))
    assert np.allclose(T[:3, 3] * 1000, [-468.557, -277.357, 895.660], atol=0.01)
    T0 = analytic.fk(NOVA5, np.zeros(6))
    assert np.allclose(T0[:3, 3] * 1000, [0.0, -223.328, 1090.0], atol=1e-6)
    assert np.allclose(T0[:3, 2], [0, -1, 0], atol=1e-12)  # flange z along -Y at zero
    reach = analytic.fk(NOVA5, np.deg2rad([0, 90, 0, 0, 0, 0]))
    assert np.allclose(reach[:3, 3] * 1000, [-850.0, -223.328, 240.0], atol=1e-6)


@pytest.mark.parametrize("name", ROBOTS)
def test_urdf_fk_equals_dh_fk(name):
    arm = load_arm(name)
    kin = Kinematics(arm)
    rng = np.random.default_rng(3)
    flange = flange_link(arm.spec)
    # Nova5: the vendor URDF's rounded 1.5708 rad leaves µm-level differences (spec §6.3)
    tol = 2e-5 if name == "nova5" else 1e-9
    for q in random_q(arm.spec, rng, 100):
        assert np.allclose(kin.fk(q, flange), analytic.fk(arm.spec, q), atol=tol)
        # the tool tip is the flange times the configured offset
        assert np.allclose(kin.fk(q), kin.fk(q, flange) @ arm.T_flange_tool, atol=1e-12)


def test_tool_offset_is_configurable():
    tool = ToolGeometry(tip_xyz=(0.01, -0.02, 0.2), tip_rpy=(0.0, 0.0, math.pi / 2))
    kin = Kinematics(load_arm("nova5", tool))
    q = np.deg2rad([10, 20, 30, 40, 50, 60])
    T_flange = analytic.fk(NOVA5, q)
    T_tool = kin.fk(q)
    assert np.allclose(T_tool[:3, 3], T_flange[:3, 3] + T_flange[:3, :3] @ [0.01, -0.02, 0.2], atol=2e-5)
    assert np.allclose(T_tool[:3, 0], T_flange[:3, 1], atol=1e-4)  # rotated 90° about the flange z


@pytest.mark.parametrize("name", ROBOTS)
def test_collision_capsules_follow_the_kinematic_chain(name):
    """Every link's capsule pieces start/end at the DH joint origins, in any configuration."""
    arm = load_arm(name)
    kin = Kinematics(arm)
    spec = arm.spec
    segs = link_segments(spec)
    rng = np.random.default_rng(5)
    for q in random_q(spec, rng, 5):
        frames = analytic.fk_all(spec, q)
        origins = frames[:, :3, 3]
        links = [
            "base_link",
            *[
                kin.model.frames[kin.model.getFrameId(n)].name
                for n in __import__("services.kinematics.urdf", fromlist=["link_names"]).link_names(spec)[1:]
            ],
        ]
        for i in range(1, spec.dof + 1):
            T_link = kin.fk(q, links[i])
            end = T_link @ np.append(segs[i][-1][1], 1.0)
            assert np.allclose(end[:3], origins[i], atol=2e-5), (name, i)


def test_committed_urdf_files_are_current():
    assert stale_urdfs() == [], "config/robots/*.urdf are stale: run `python -m services.kinematics.urdf`"


# --- analytic IK ---------------------------------------------------------------------------------
@pytest.mark.parametrize("spec", [NOVA5, UR5E, UR3], ids=lambda s: s.name)
def test_analytic_ik_round_trip_on_1000_random_poses(spec):
    rng = np.random.default_rng(7)
    qs = random_q(spec, rng, 1000)
    Ts = analytic.fk(spec, qs)
    q_batch, valid = analytic.ik_all(spec, Ts)
    recovered = 0
    for k in range(len(qs)):
        sols = analytic.ik_solutions(spec, Ts[k])
        assert len(sols) == int(valid[k].sum())  # scalar fast path agrees with the batch
        assert len(sols) >= 1
        sols = np.array(sols)
        # every solution reproduces the pose
        assert np.allclose(analytic.fk(spec, sols), Ts[k], atol=1e-6)
        # and the configuration we started from is among them (modulo full turns)
        diff = np.abs((sols - qs[k] + np.pi) % (2 * np.pi) - np.pi)
        recovered += bool(np.any(np.max(diff, axis=1) < 1e-6))
    assert recovered == len(qs)
    # batch solutions verified by FK too
    assert np.allclose(analytic.fk(spec, q_batch[valid]), np.repeat(Ts, valid.sum(axis=1), axis=0), atol=1e-6)


def test_analytic_solutions_within_limits_sorted_nearest_seed():
    kin = Kinematics(load_arm("nova5"))
    q = np.deg2rad([10, 20, 30, 40, 50, 60])
    sols = kin.ik_analytic(kin.fk(q), seed=q + 0.01)
    assert np.allclose(sols[0], q, atol=1e-5)
    d = np.max(np.abs(sols - (q + 0.01)), axis=1)
    assert np.all(np.diff(d) >= 0)
    assert np.all(kin.limits.lower <= sols) and np.all(sols <= kin.limits.upper)


def test_solve_ik_prefers_nonsingular_and_reports_manipulability():
    kin = Kinematics(load_arm("ur5e"))
    q = np.array([0.3, -1.2, 1.4, -1.0, 1.2, 0.5])
    sol = kin.solve_ik(kin.fk(q), q)
    assert sol.method == "analytic"
    assert np.allclose(sol.q, q, atol=1e-6)
    assert sol.manipulability == pytest.approx(kin.manipulability(q))
    assert sol.manipulability > 1e-3
    assert sol.position_error_m < 1e-6
    # wrist singularity (θ5 = 0) has zero manipulability
    assert kin.manipulability(np.array([0.3, -1.2, 1.4, -1.0, 0.0, 0.5])) < 1e-9


def test_unreachable_pose_raises_ik_failure_with_the_pose():
    kin = Kinematics(load_arm("nova5"))
    T = make_transform(np.eye(3), [1.7, 0.2, 0.3])
    with pytest.raises(IKFailureError, match=r"1\.7000, 0\.2000, 0\.3000"):
        kin.solve_ik(T, np.zeros(6))
    with pytest.raises(IKFailureError, match=r"1\.7000, 0\.2000, 0\.3000"):
        kin.solve_ik(T, np.zeros(6), method="numeric")
    with pytest.raises(IKFailureError, match=r"1\.7000"):
        analytic.solve_nearest(NOVA5, T, np.zeros(6))


@pytest.mark.parametrize(
    "bad",
    [np.full((4, 4), np.nan), np.eye(3), np.diag([1.0, 1.0, -1.0, 1.0]), "pose"],
    ids=["nan", "shape", "reflection", "text"],
)
def test_bad_pose_is_invalid_input(bad):
    kin = Kinematics(load_arm("nova5"))
    with pytest.raises(InvalidInputError):
        kin.solve_ik(bad, np.zeros(6))


def test_bad_seed_and_joints_are_invalid_input():
    kin = Kinematics(load_arm("nova5"))
    T = kin.fk(np.deg2rad([0, 10, 80, 0, -90, 0]))
    with pytest.raises(InvalidInputError, match="NaN"):
        kin.solve_ik(T, [0, 0, np.nan, 0, 0, 0])
    with pytest.raises(InvalidInputError, match="6 values"):
        kin.solve_ik(T, [0, 0, 0])
    with pytest.raises(InvalidInputError, match="NaN"):
        kin.fk([np.nan] * 6)
    with pytest.raises(InvalidInputError, match="method"):
        kin.solve_ik(T, np.zeros(6), method="magic")


def test_unknown_robot_is_a_configuration_error():
    with pytest.raises(ConfigurationError, match="kuka"):
        get_robot("kuka")


# --- numerical IK --------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ROBOTS)
def test_numeric_ik_from_a_cold_seed(name):
    kin = Kinematics(load_arm(name))
    rng = np.random.default_rng(11)
    cold = np.deg2rad([0, 0, 90, 0, -90, 0]) if name == "nova5" else np.zeros(6)
    for k, q in enumerate(random_q(kin.spec, rng, 60)):
        T = kin.fk(q)
        sol = kin.ik_numeric(T, cold, rng=np.random.default_rng(k))
        pos, rot = kin.pose_error(sol, T)
        assert pos < 1e-6 and rot < 1e-6
        assert np.all(sol >= kin.limits.lower) and np.all(sol <= kin.limits.upper)


@settings(max_examples=40, deadline=None)
@given(
    q=st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6),
    turns=st.lists(st.sampled_from([-1, 0, 1]), min_size=6, max_size=6),
    noise=st.floats(-0.2, 0.2),
)
def test_numeric_ik_never_flips_a_full_turn(q, turns, noise):
    """The seed sits on another turn of the ±360° joints: the answer stays on the seed's turn."""
    kin = Kinematics(load_arm("nova5"))
    q = np.clip(np.array(q), -2.7, 2.7)
    cont = kin.limits.continuous()
    seed = q + np.where(cont, 2 * np.pi * np.array(turns), 0.0) + noise
    seed = np.clip(seed, kin.limits.lower, kin.limits.upper)
    sol = kin.ik_numeric(kin.fk(q), seed, rng=np.random.default_rng(0))
    assert kin.pose_error(sol, kin.fk(q))[0] < 1e-6
    # on every full-turn joint the solution is the equivalent angle nearest the seed within limits
    for j in np.flatnonzero(cont):
        options = sol[j] + 2 * np.pi * np.arange(-3, 4)
        options = options[(options >= kin.limits.lower[j]) & (options <= kin.limits.upper[j])]
        assert abs(sol[j] - seed[j]) <= np.min(np.abs(options - seed[j])) + 1e-9


def test_numeric_ik_on_any_urdf_and_tool_frame():
    """A URDF read as a generic arm (no closed form): numerical IK to its Link5 frame."""
    urdf = load_arm("nova5").urdf
    arm = arm_from_urdf(urdf, "Link5", name="generic")
    kin = Kinematics(arm)
    assert not kin.has_analytic_ik()
    rng = np.random.default_rng(13)
    for k, q in enumerate(random_q(arm.spec, rng, 20)):
        T = kin.fk(q)
        sol = kin.solve_ik(T, np.zeros(6), rng=np.random.default_rng(k))
        assert sol.method == "numeric" and sol.position_error_m < 1e-6
    with pytest.raises(ConfigurationError, match="no frame"):
        arm_from_urdf(urdf, "gripper_tip")
    with pytest.raises(ConfigurationError, match="URDF"):
        arm_from_urdf("<robot>", "x")
