"""The simulated RealSense: intrinsics, metric depth, noise, determinism, frame sets on disk."""

from __future__ import annotations

import json
from collections.abc import Iterator

import numpy as np
import pytest
from typer.testing import CliRunner

from services.common.errors import CameraConnectionError, InvalidInputError
from services.common.frames import check_transform, invert_transform
from services.common.sensors import Camera
from services.sim.twin import TwinEngine, create_twin_engine
from services.sim.twin import ground_truth as gt
from services.sim.twin.camera import TwinCamera
from services.sim.twin.cli import app
from services.sim.twin.dataset import LABEL_OBSTACLE, load_sim_scene, write_sim_scene
from tests.sim.twin_helpers import twin_settings

SEED = 3


@pytest.fixture(scope="module")
def engine() -> Iterator[TwinEngine]:
    eng = create_twin_engine(twin_settings(), seed=SEED)
    eng.settle(0.2)
    yield eng
    eng.close()


@pytest.fixture(scope="module")
def clean_cam(engine: TwinEngine) -> Iterator[TwinCamera]:
    cam = TwinCamera(engine, seed=1, noise=False)
    yield cam
    cam.close()


@pytest.fixture(scope="module")
def noisy_cam(engine: TwinEngine) -> Iterator[TwinCamera]:
    cam = TwinCamera(engine, seed=1, noise=True)
    yield cam
    cam.close()


def pixel_rays(cam: TwinCamera) -> np.ndarray:
    K = cam.intrinsics
    u, v = np.meshgrid(np.arange(K.width), np.arange(K.height))
    return np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(u.shape)], axis=-1)


def project(cam: TwinCamera, T_camera_base: np.ndarray, p_base: np.ndarray) -> tuple[int, int]:
    p = T_camera_base[:3, :3] @ p_base + T_camera_base[:3, 3]
    K = cam.intrinsics
    return round(K.fx * p[0] / p[2] + K.cx), round(K.fy * p[1] / p[2] + K.cy)


def test_camera_protocol_and_d435i_intrinsics(clean_cam: TwinCamera) -> None:
    assert isinstance(clean_cam, Camera)
    K = clean_cam.intrinsics
    assert (K.width, K.height) == (640, 480)
    assert K.fx == pytest.approx(617.0, abs=1.0) and K.fx == K.fy
    vfov = 2 * np.degrees(np.arctan(K.height / 2 / K.fy))
    assert vfov == pytest.approx(42.5, abs=1e-6)
    frame = clean_cam.capture().validate()
    assert frame.depth.dtype == np.uint16 and frame.depth_scale == 0.001
    assert frame.color.dtype == np.uint8 and frame.color.shape == (480, 640, 3)


def test_depth_matches_the_table_plane_within_1mm_without_noise(
    engine: TwinEngine, clean_cam: TwinCamera
) -> None:
    frame, views = clean_cam.capture_with_views()
    T = gt.T_base_camera(engine.world.twin.camera)
    check_transform(T)
    rays_base = pixel_rays(clean_cam) @ T[:3, :3].T
    z_plane = -T[2, 3] / rays_base[..., 2]  # optical-axis depth of the table plane z = 0 per pixel
    table = views.geom_id == 0
    assert table.mean() > 0.5
    assert np.max(np.abs(views.depth_m[table] - z_plane[table])) < 0.001
    z16 = frame.depth_m()[table]
    assert np.max(np.abs(z16 - z_plane[table])) <= 0.0005 + 1e-6  # z16 rounding only
    # plausible working distance for the mount: ~0.8 m at the image centre
    assert 0.6 < views.depth_m[240, 320] < 1.0


def test_ground_truth_poses_project_onto_their_objects(engine: TwinEngine, clean_cam: TwinCamera) -> None:
    _, views = clean_cam.capture_with_views()
    T_camera_base = invert_transform(gt.T_base_camera(engine.world.twin.camera))
    geom_of = {engine.world.geom_name(g): g for g in range(engine.model.ngeom)}
    for obj in engine.scene.objects:
        T = gt.object_pose(engine, obj.name)
        top = T[:3, 3] + np.array([0.0, 0.0, obj.size_m[0] / 2 - 0.002])  # just under the top surface
        u, v = project(clean_cam, T_camera_base, top)
        assert views.geom_id[v, u] == geom_of[f"{obj.name}_geom"], obj.name
        # and the depth there is the distance to that surface point along the optical axis
        p_cam = T_camera_base[:3, :3] @ (top + [0, 0, 0.002]) + T_camera_base[:3, 3]
        assert views.depth_m[v, u] == pytest.approx(p_cam[2], abs=0.004)


def test_noise_makes_holes_on_the_rod_and_noisy_depth_elsewhere(
    engine: TwinEngine, noisy_cam: TwinCamera
) -> None:
    frame, views = noisy_cam.capture_with_views()
    rod_geom = next(g for g in range(engine.model.ngeom) if engine.world.geom_name(g) == "rod_geom")
    rod = views.geom_id == rod_geom
    assert rod.sum() > 500
    assert np.all(views.depth_m[rod] > 0)  # the clean render has depth on the rod
    holes_on_rod = (frame.depth[rod] == 0).mean()
    assert holes_on_rod == pytest.approx(engine.world.twin.camera.hole_fraction, abs=0.12)
    table = views.geom_id == 0
    assert (frame.depth[table] == 0).mean() < 0.02  # the table keeps its depth (apart from edges)
    err = frame.depth_m()[table] - views.depth_m[table]
    valid = frame.depth[table] > 0
    assert 0.001 < np.std(err[valid]) < 0.006  # ~2–4 mm at 0.7–1 m
    assert not np.array_equal(frame.color, views.color)


def test_same_seed_gives_identical_scene_and_frames(engine: TwinEngine, noisy_cam: TwinCamera) -> None:
    other = create_twin_engine(twin_settings(), seed=SEED)
    other.settle(0.2)
    cam_a, cam_b = TwinCamera(engine, seed=42, noise=True), TwinCamera(other, seed=42, noise=True)
    try:
        assert other.scene == engine.scene
        fa, fb = cam_a.capture(), cam_b.capture()
        assert np.array_equal(fa.color, fb.color) and np.array_equal(fa.depth, fb.depth)
        fa2 = cam_a.capture()  # the next frame of the same camera has fresh noise
        assert not np.array_equal(fa.depth, fa2.depth)
    finally:
        cam_a.close()
        cam_b.close()
    different = create_twin_engine(twin_settings(), seed=SEED + 1)
    assert different.scene != engine.scene


def test_a_ready_camera_has_its_renderer_and_takes_the_same_frames(engine: TwinEngine) -> None:
    """``ready`` sets the renderer up before anyone waits for a frame, and takes none: its first frame
    is the first a camera of that seed takes (same noise, seq 1)."""
    ready, fresh = TwinCamera.ready(engine, seed=42), TwinCamera(engine, seed=42)
    try:
        assert ready._renderer is not None and fresh._renderer is None
        fr, ff = ready.capture(), fresh.capture()
        assert fr.seq == ff.seq == 1
        assert np.array_equal(fr.color, ff.color) and np.array_equal(fr.depth, ff.depth)
    finally:
        ready.close()
        fresh.close()


def test_closed_camera_raises(engine: TwinEngine) -> None:
    cam = TwinCamera(engine, seed=0, noise=False)
    cam.close()
    with pytest.raises(CameraConnectionError, match="closed"):
        cam.capture()


def test_sim_scene_frame_set_round_trip(tmp_path) -> None:  # type: ignore[no-untyped-def]
    settings = twin_settings()
    path = write_sim_scene(5, tmp_path / "scene5", settings, frames=2, noise=True)
    record = load_sim_scene(tmp_path / "scene5")
    truth = json.loads(path.read_text())
    assert truth["seed"] == 5 and len(record.frames) == 2 and len(record.labels) == 2
    T_base_camera = np.array(truth["T_base_camera"])
    check_transform(T_base_camera)
    assert np.allclose(T_base_camera, gt.T_base_camera(settings.sim.twin.camera))
    names = [o["name"] for o in truth["objects"]]
    assert names == ["rod", "cube_red", "cube_blue", "cube_green", "cube_black"]
    for o in truth["objects"]:
        T_b, T_c = np.array(o["T_base_object"]), np.array(o["T_camera_object"])
        assert np.allclose(T_base_camera @ T_c, T_b, atol=1e-9)
        assert (record.labels[0] == o["label"]).sum() > 300  # every object is in view
    assert (record.labels[0] == LABEL_OBSTACLE).sum() > 10000  # seed 004's obstacle size rule
    f0, f1 = record.frames
    assert f0.intrinsics.fx == pytest.approx(617.0, abs=1.0)
    assert not np.array_equal(f0.depth, f1.depth)  # independent noise per frame
    assert np.array_equal(record.labels[0], record.labels[1])  # same scene
    again = write_sim_scene(5, tmp_path / "again", settings, frames=1, noise=True)
    assert json.loads(again.read_text())["objects"] == truth["objects"]
    assert np.array_equal(load_sim_scene(tmp_path / "again").frames[0].depth, f0.depth)


def test_sim_scene_bad_input(tmp_path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InvalidInputError, match="frames"):
        write_sim_scene(1, tmp_path, twin_settings(), frames=0)
    with pytest.raises(InvalidInputError, match="seed"):
        write_sim_scene(-3, tmp_path, twin_settings())
    with pytest.raises(InvalidInputError, match="not a sim scene"):
        load_sim_scene(tmp_path)
    result = CliRunner().invoke(app, ["sim-scene", "--seed", "1", "--out", str(tmp_path), "--frames", "0"])
    assert result.exit_code != 0


def test_cli_writes_the_mjcf(tmp_path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "cell.xml"
    result = CliRunner().invoke(app, ["sim-mjcf", "--seed", "2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    text = out.read_text()
    assert "<mujoco" in text and 'name="rod"' in text and 'name="realsense"' in text


def test_capture_while_physics_steps_in_another_thread() -> None:
    import threading

    from tests.sim.twin_helpers import HOME

    eng = create_twin_engine(twin_settings(), seed=SEED)
    cam = TwinCamera(eng, seed=0, noise=True)
    stop = threading.Event()
    errors: list[BaseException] = []

    def physics() -> None:
        try:
            while not stop.is_set():
                eng.step(0.008, HOME, np.zeros(6), np.zeros(6))
        except BaseException as exc:
            errors.append(exc)

    worker = threading.Thread(target=physics, name="twin-physics")
    worker.start()
    try:
        stamps = [cam.capture().validate().stamp_ns for _ in range(3)]
    finally:
        stop.set()
        worker.join(5.0)
        cam.close()
    assert not errors and not worker.is_alive()
    assert stamps == sorted(stamps) and stamps[-1] > stamps[0]  # frames follow sim time
