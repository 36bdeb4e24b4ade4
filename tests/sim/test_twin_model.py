"""The twin's model: MJCF kinematics = analytic FK, contact settings, seeded scenes, validation."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from services.common.errors import ConfigurationError, InvalidInputError
from services.kinematics.analytic import fk
from services.sim.twin import mjcf
from services.sim.twin.model import build_world
from services.sim.twin.scene import hollow_tube_inertia, sample_scene
from tests.sim.twin_helpers import twin_settings


@pytest.mark.parametrize("robot", ["nova5", "ur5e", "ur3"])
def test_flange_and_tool_sites_match_analytic_fk(robot: str) -> None:
    settings = twin_settings({"cubes": [], "rod": False, "obstacle": False}, robot={"model": robot})
    world = build_world(settings, seed=0)
    data = mujoco.MjData(world.model)
    rng = np.random.default_rng(7)
    spec = world.spec
    lo, hi = np.maximum(spec.lower, -np.pi), np.minimum(spec.upper, np.pi)
    for q in rng.uniform(lo, hi, size=(25, 6)):
        data.qpos[world.arm_qpos] = q
        mujoco.mj_kinematics(world.model, data)
        T = fk(spec, q)
        assert np.allclose(data.site_xpos[world.flange_site], T[:3, 3], atol=1e-6)
        assert np.allclose(data.site_xmat[world.flange_site].reshape(3, 3), T[:3, :3], atol=1e-6)
        tool = T @ np.array([0, 0, settings.gripper.tcp_offset_m, 1.0])
        assert np.allclose(data.site_xpos[world.tool_site], tool[:3], atol=1e-6)


def test_contact_settings_are_the_documented_ones() -> None:
    settings = twin_settings()
    world = build_world(settings, seed=1)
    m, phys = world.model, settings.sim.twin.physics
    assert m.opt.impratio == pytest.approx(phys.impratio) and phys.impratio >= 10
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_MULTICCD
    assert m.opt.timestep == pytest.approx(phys.timestep_s)
    for name in mjcf.PAD_GEOMS:
        g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
        assert m.geom_condim[g] == 4
        assert m.geom_friction[g][0] == pytest.approx(phys.pad_friction)
        assert m.geom_priority[g] > 0  # the pad's friction wins over the object's
    rod = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "rod_geom")
    assert m.geom_type[rod] == mujoco.mjtGeom.mjGEOM_CYLINDER  # flat ends: it can stand


def test_rod_has_hollow_tube_inertia_and_mass() -> None:
    settings = twin_settings()
    world = build_world(settings, seed=2)
    sc = settings.sim.twin.scene
    body = world.object_body["rod"]
    assert world.model.body_mass[body] == pytest.approx(sc.rod_mass_kg)
    r_o, r_i = sc.rod_diameter_m / 2, sc.rod_diameter_m / 2 - sc.rod_wall_m
    i_perp, i_axial = hollow_tube_inertia(sc.rod_mass_kg, r_o, r_i, sc.rod_length_m)
    assert np.allclose(sorted(world.model.body_inertia[body]), sorted([i_perp, i_perp, i_axial]), rtol=1e-6)
    # a hollow tube has more axial inertia than the solid rod of the same mass, less than a thin shell
    assert sc.rod_mass_kg * r_o**2 / 2 < i_axial < sc.rod_mass_kg * r_o**2


def test_gripper_drive_is_coupled_and_force_limited() -> None:
    settings = twin_settings({"cubes": [], "rod": False})
    world = build_world(settings, seed=0)
    m = world.model
    assert m.neq == 1 and m.eq_type[0] == mujoco.mjtEq.mjEQ_JOINT  # fingers coupled
    grip = settings.sim.twin.physics.grip_force_n
    assert np.allclose(m.actuator_forcerange[world.grip_act], [-grip, grip])
    assert all(m.actuator_forcerange[a][1] > 0 for a in world.arm_act)


def test_same_seed_same_scene_and_different_seed_different_scene() -> None:
    sc = twin_settings().sim.twin.scene
    a, b, c = sample_scene(sc, 11), sample_scene(sc, 11), sample_scene(sc, 12)
    assert a == b
    assert [o.position_m for o in a.objects] != [o.position_m for o in c.objects]
    assert build_world(twin_settings(), 11).xml == build_world(twin_settings(), 11).xml


def test_scene_objects_lie_in_the_pick_zone_apart() -> None:
    sc = twin_settings().sim.twin.scene
    lo, hi = np.array(sc.pick_zone_min_m), np.array(sc.pick_zone_max_m)
    for seed in range(20):
        scene = sample_scene(sc, seed)
        assert [o.name for o in scene.objects] == ["rod", *(f"cube_{c}" for c in sc.cubes)]
        xy = np.array([o.position_m[:2] for o in scene.objects])
        assert np.all(xy >= lo) and np.all(xy <= hi)
        rod = scene.get("rod")
        axis = rod.T_base_object[:3, 2]
        assert abs(axis[2]) < 1e-9  # lying on its side
        assert rod.position_m[2] == pytest.approx(sc.rod_diameter_m / 2)
        ends = [np.array(rod.position_m[:2]) + s * sc.rod_length_m / 2 * axis[:2] for s in (-1, 1)]
        for e in ends:
            assert np.all(e >= lo - 1e-9) and np.all(e <= hi + 1e-9)
        cubes = xy[1:]
        for i in range(len(cubes)):
            for j in range(i + 1, len(cubes)):
                assert (
                    np.linalg.norm(cubes[i] - cubes[j])
                    >= 2 * sc.cube_size_m / np.sqrt(2) + sc.min_gap_m - 1e-9
                )


def test_impossible_layout_and_bad_seed_are_clear_errors() -> None:
    crowded = twin_settings({"pick_zone_min_m": (0.4, -0.05), "pick_zone_max_m": (0.5, 0.05)}).sim.twin.scene
    with pytest.raises(InvalidInputError, match="cannot place"):
        sample_scene(crowded, 0)
    with pytest.raises(InvalidInputError, match="seed"):
        sample_scene(twin_settings().sim.twin.scene, -1)


@pytest.mark.parametrize(
    ("section", "match"),
    [
        ({"physics": {"cone": "pyramidal"}}, "pyramidal"),
        ({"scene": {"cubes": ["red"], "drop_zones_m": {"blue": (0.3, 0.4)}}}, "drop zone"),
        ({"scene": {"pick_zone_min_m": (0.6, 0.0), "pick_zone_max_m": (0.4, 0.1)}}, "pick zone"),
        ({"camera": {"position_m": (0.5, 0.0, 0.0), "look_at_m": (0.5, 0.0, 0.0)}}, "must differ"),
        ({"physics": {"impratio": 0.5}}, "impratio"),
    ],
)
def test_bad_twin_settings_are_rejected(section: dict, match: str) -> None:
    from services.common.settings import load_settings

    with pytest.raises(ConfigurationError, match=match):
        load_settings("sim", overrides={"sim": {"twin": section}})


def test_ground_truth_stays_out_of_perception_and_planning_code() -> None:
    """Only evaluation may read the twin's ground truth: no import from the pipeline's cores."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "services"
    pattern = re.compile(
        r"^\s*(from|import)\s+services\.sim\.twin(\.ground_truth|\s+import\s+.*ground_truth)", re.M
    )
    offenders = [
        str(path.relative_to(root))
        for area in ("vision", "grasp", "motion", "task", "robot")
        for path in (root / area).rglob("*.py")
        if pattern.search(path.read_text())
    ]
    assert offenders == []
