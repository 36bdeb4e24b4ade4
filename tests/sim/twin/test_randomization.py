"""Per-trial worlds of the twin: seeded draws within the configured ranges, carried into the physics, the
drive, the camera and the ground truth — while the frames still report the nominal intrinsics."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import mujoco
import numpy as np
import pytest
from pydantic import ValidationError

from services.common.settings import Settings
from services.common.settings.sim import TwinRandomizationSettings
from services.sim.twin import TwinEngine, build_world, sample_scene
from services.sim.twin import ground_truth as gt
from services.sim.twin.camera import TwinCamera, true_intrinsics, twin_intrinsics
from services.sim.twin.randomization import (
    Variation,
    nominal_variation,
    record_ranges,
    sample_variation,
    variation_for,
)
from services.sim.twin.trial import TICK_S
from tests.sim.twin_helpers import HOME, twin_settings


def randomized(**scene: object) -> Settings:
    s = twin_settings(scene=dict(scene) if scene else None)
    rnd = s.sim.twin.randomization.model_copy(update={"enabled": True})
    return s.model_copy(
        update={
            "sim": s.sim.model_copy(update={"twin": s.sim.twin.model_copy(update={"randomization": rnd})})
        }
    )


def world_with(settings: Settings, seed: int, **values: object) -> TwinEngine:
    v = dataclasses.replace(sample_variation(settings.sim.twin, seed), **values)
    return TwinEngine(build_world(settings, seed, variation=v), HOME)


@pytest.fixture
def raised() -> Iterator[TwinEngine]:
    """A world 5 mm above the base plane, camera knocked by the full range, intrinsics off by the full range."""
    eng = world_with(
        randomized(),
        5,
        table_height_m=0.005,
        camera_offset_m=(0.002, -0.002, 0.002),
        camera_rotation_deg=(0.5, -0.5, 0.5),
        focal_scale=1.005,
        principal_offset_px=(2.0, -2.0),
    )
    eng.settle(0.3)
    yield eng
    eng.close()


def test_each_seed_draws_its_own_world_within_the_configured_ranges() -> None:
    twin = randomized().sim.twin
    ranges = record_ranges(twin)
    records = [sample_variation(twin, seed).record() for seed in range(300)]
    assert sample_variation(twin, 7) == sample_variation(twin, 7)  # seeded
    for key, (lo, hi) in ranges.items():
        values = np.array([r[key] for r in records])
        assert np.all(values >= lo - 1e-3) and np.all(values <= hi + 1e-3), key
        # the draws spread over the range (uniform), not a constant
        assert values.std() > (hi - lo) / 10, key
    assert set(records[0]) == set(ranges)


def test_randomization_is_off_unless_asked_and_the_nominal_world_is_the_configured_one() -> None:
    s = twin_settings()
    assert not s.sim.twin.randomization.enabled
    world = build_world(s, 3)
    assert world.variation == nominal_variation(s.sim.twin) and not world.variation.randomized
    assert variation_for(randomized().sim.twin, 3).randomized
    # nominal: the rod has no friction of its own, the table is the base plane
    assert world.scene.table_z_m == 0.0 and world.scene.get("rod").friction is None


def test_a_randomized_world_carries_its_draw_into_the_physics() -> None:
    s = randomized()
    v = sample_variation(s.sim.twin, 11)
    w = build_world(s, 11)
    assert w.variation == v
    m = w.model
    rod = w.scene.get("rod")
    geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "rod_geom")
    assert m.geom_size[geom][:2] == pytest.approx([v.rod_diameter_m / 2, v.rod_length_m / 2])
    assert m.body_mass[w.object_body["rod"]] == pytest.approx(v.rod_mass_kg)
    assert m.geom_friction[geom][0] == pytest.approx(v.rod_table_friction) and m.geom_priority[geom] == 1
    pads = np.flatnonzero(w.pad_geom)
    assert np.allclose(m.geom_friction[pads, 0], v.pad_friction) and np.all(m.geom_priority[pads] == 2)
    assert m.actuator_forcerange[w.grip_act][1] == pytest.approx(v.grip_force_n)
    table = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "table")
    assert m.geom_pos[table][2] == pytest.approx(v.table_height_m)
    assert rod.position_m[2] == pytest.approx(v.table_height_m + v.rod_diameter_m / 2)
    assert w.scene.obstacle is not None
    assert w.scene.obstacle.center_m[2] == pytest.approx(
        s.sim.twin.scene.obstacle_center_m[2] + v.table_height_m
    )
    # the drive: critically damped PD at the drawn bandwidth (kp ∝ ω², kv ∝ ω)
    nominal = build_world(twin_settings(), 11)
    ratio = v.tracking_bandwidth_rad_s / s.sim.twin.physics.tracking_bandwidth_rad_s
    assert np.asarray(w.gains.kp) / np.asarray(nominal.gains.kp) == pytest.approx(ratio**2, rel=0.02)
    assert np.asarray(w.gains.kv) / np.asarray(nominal.gains.kv) == pytest.approx(ratio, rel=0.02)


def test_the_layout_of_a_seed_does_not_move_when_its_world_is_randomized() -> None:
    """Randomization draws on its own stream: same seed, same places (only the rod's size differs)."""
    s, r = twin_settings(), randomized()
    for seed in range(5):
        a, b = build_world(s, seed).scene, build_world(r, seed).scene
        for oa, ob in zip(a.objects, b.objects, strict=True):
            assert oa.position_m[:2] == pytest.approx(ob.position_m[:2], abs=1e-12), (seed, oa.name)


def test_the_camera_renders_its_true_mount_and_intrinsics_and_reports_the_nominal_ones(
    raised: TwinEngine,
) -> None:
    cam_cfg = raised.world.twin.camera
    cam = TwinCamera(raised, seed=1, noise=False)
    try:
        frame, views = cam.capture_with_views()
    finally:
        cam.close()
    assert frame.intrinsics == twin_intrinsics(cam_cfg)  # what the cell is told

    def table_depth_error(T: np.ndarray, K) -> float:  # type: ignore[no-untyped-def]
        u, v = np.meshgrid(np.arange(K.width), np.arange(K.height))
        rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(u.shape)], axis=-1) @ T[:3, :3].T
        z = (raised.scene.table_z_m - T[2, 3]) / rays[..., 2]
        table = views.geom_id == 0
        return float(np.max(np.abs(views.depth_m[table] - z[table])))

    truth = table_depth_error(gt.true_T_base_camera(raised), true_intrinsics(cam_cfg, raised.world.variation))
    told = table_depth_error(gt.T_base_camera(cam_cfg), frame.intrinsics)
    assert truth < 0.001  # the render is exactly the true camera over the raised table
    assert told > 0.01  # and the nominal camera the cell uses is centimetres off at the image edges


def test_ground_truth_judges_the_rod_against_the_raised_table(raised: TwinEngine) -> None:
    check = gt.check_rod_standing(raised)
    assert abs(check.lowest_point_m) < 0.001  # lying on the table 5 mm above the base plane
    assert not any("not on the table" in r for r in check.reasons)


def test_command_latency_delays_the_drive_by_whole_physics_steps() -> None:
    s = twin_settings(scene={"cubes": [], "rod": False, "obstacle": False})
    prompt = world_with(s, 0, randomized=True, command_latency_s=0.0)
    late = world_with(s, 0, randomized=True, command_latency_s=0.016)  # 8 steps of 2 ms = 2 ticks
    assert late._latency_steps == 8
    qd = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0])  # wrist 3 at 1 rad/s
    moved = {}
    for name, eng in (("prompt", prompt), ("late", late)):
        q0 = eng.state().q.copy()
        steps = []
        for k in range(1, 5):
            st = eng.step(TICK_S, HOME + qd * k * TICK_S, qd, np.zeros(6))
            steps.append(abs(float(st.q[5] - q0[5])))
        moved[name] = steps
        eng.close()
    assert moved["prompt"][0] > 1e-3  # follows within the first tick
    assert moved["late"][1] < 1e-5  # still at rest after two ticks: the command has not arrived
    assert moved["late"][3] > 1e-3  # then follows


def test_camera_noise_and_highlights_follow_the_world() -> None:
    s = randomized(cubes=[], obstacle=False)
    shares, peaks = [], []
    for holes, gain in ((0.2, 2.0), (0.5, 6.0)):
        eng = world_with(s, 2, hole_fraction=holes, highlight_gain=gain, light_scale=1.0)
        eng.settle(0.2)
        cam = TwinCamera(eng, seed=1)
        try:
            frame, views = cam.capture_with_views()
        finally:
            cam.close()
            eng.close()
        rod_geom = next(g for g in range(eng.model.ngeom) if eng.world.geom_name(g) == "rod_geom")
        rod = views.geom_id == rod_geom
        assert rod.sum() > 300
        shares.append(float((frame.depth[rod] == 0).mean()))
        peaks.append(float(np.percentile(frame.color[rod].max(axis=1), 99)))
    assert shares[0] == pytest.approx(0.2, abs=0.12) and shares[1] == pytest.approx(0.5, abs=0.12)
    assert peaks[1] > peaks[0] + 20  # a stronger highlight stripe on the rod


def test_sample_scene_raises_every_object_with_the_table() -> None:
    sc = twin_settings().sim.twin.scene
    flat, raised_scene = sample_scene(sc, 4), sample_scene(sc, 4, table_z_m=0.003, rod_friction=0.3)
    for a, b in zip(flat.objects, raised_scene.objects, strict=True):
        assert b.position_m[2] == pytest.approx(a.position_m[2] + 0.003)
    assert raised_scene.get("rod").friction == 0.3 and raised_scene.table_z_m == 0.003


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("rod_mass_scale", (1.2, 0.8), "rod_mass_scale"),
        ("grip_force_scale", (0.0, 1.2), "grip_force_scale"),
        ("command_latency_s", (0.0, 0.5), "command_latency_s"),
        ("hole_fraction", (0.2, 1.5), "hole_fraction"),
    ],
)
def test_a_bad_range_is_refused_naming_it(field: str, value: tuple[float, float], match: str) -> None:
    with pytest.raises(ValidationError, match=match):
        TwinRandomizationSettings(**{field: value})


def test_variation_record_is_in_human_units() -> None:
    v: Variation = sample_variation(randomized().sim.twin, 1)
    r = v.record()
    assert r["rod_diameter_mm"] == pytest.approx(v.rod_diameter_m * 1000, abs=1e-3)
    assert r["command_latency_ms"] == pytest.approx(v.command_latency_s * 1000, abs=1e-3)
    assert r["camera_offset_mm"] == pytest.approx(np.linalg.norm(v.camera_offset_m) * 1000, abs=1e-3)
