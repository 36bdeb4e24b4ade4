"""Frame sets of seeded twin scenes, with ground truth — the data vision tests and benchmarks use.

``write_sim_scene(seed, out_dir)`` writes into ``out_dir``:

- ``color_000.png`` (8-bit colour), ``depth_000.png`` (16-bit, units of ``depth_scale`` m),
  ``labels_000.png`` (8-bit instance labels from the noise-free render), one triple per frame;
- ``intrinsics.json``: the colour stream's pinhole intrinsics (depth is aligned to it);
- ``ground_truth.json``: seed, T_base_camera, every object's pose in the base and camera frames,
  size, colour and label value, the obstacle box, the layout (pick and drop zones), the robot's
  joints. Label values: 0 table/background, 1..N the objects in order, 100 obstacle, 200 robot.

Frames of one set show the same (settled) scene; with noise on they differ only by sensor noise.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from services.common.errors import InvalidInputError
from services.common.frames import invert_transform, make_transform
from services.common.sensors import CameraIntrinsics, RGBDFrame, write_intrinsics
from services.common.settings import Settings, load_settings
from services.sim.twin import ground_truth as gt
from services.sim.twin.camera import DEPTH_SCALE, TwinCamera
from services.sim.twin.engine import TwinEngine, create_twin_engine

Array = np.ndarray

LABEL_OBSTACLE = 100
LABEL_ROBOT = 200
MAX_FRAMES = 1000


@dataclass(frozen=True)
class SimSceneRecord:
    frames: list[RGBDFrame]
    labels: list[Array]
    truth: dict[str, Any]


def _mat(T: Array) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.asarray(T)]


def label_image(engine: TwinEngine, geom_id: Array) -> Array:
    """Per-pixel instance labels (uint8) from a geom-id image."""
    w = engine.world
    lut = np.zeros(engine.model.ngeom + 1, dtype=np.uint8)  # last entry: geom id −1
    for g in range(engine.model.ngeom):
        if w.geom_object[g] >= 0:
            lut[g] = w.geom_object[g] + 1
        elif w.robot_geom[g] or engine.world.geom_name(g) == "robot_base":
            lut[g] = LABEL_ROBOT
        elif w.env_geom[g] and w.scene.obstacle is not None and w.geom_name(g) == w.scene.obstacle.name:
            lut[g] = LABEL_OBSTACLE
    return lut[geom_id]


def scene_truth(engine: TwinEngine, settings: Settings) -> dict[str, Any]:
    """Ground truth of the engine's current state as a JSON-ready dict."""
    T_base_camera = gt.true_T_base_camera(engine)
    T_camera_base = invert_transform(T_base_camera)
    objects = []
    for k, obj in enumerate(engine.scene.objects):
        T = gt.object_pose(engine, obj.name)
        objects.append(
            {
                "name": obj.name,
                "kind": obj.kind,
                "color": obj.color,
                "size_m": list(obj.size_m),
                "mass_kg": obj.mass_kg,
                "label": k + 1,
                "T_base_object": _mat(T),
                "T_camera_object": _mat(T_camera_base @ T),
            }
        )
    obstacle = None
    if engine.scene.obstacle is not None:
        ob = engine.scene.obstacle
        T = make_transform(np.eye(3), ob.center_m)
        obstacle = {
            "name": ob.name,
            "center_m": list(ob.center_m),
            "half_size_m": list(ob.half_size_m),
            "label": LABEL_OBSTACLE,
            "T_base_object": _mat(T),
            "T_camera_object": _mat(T_camera_base @ T),
        }
    scene_cfg = engine.world.twin.scene
    cam = engine.world.twin.camera
    return {
        "seed": engine.scene.seed,
        "frame_convention": "T_a_b maps points in frame b to frame a; camera = optical frame (x right, y down)",
        "T_base_camera": _mat(T_base_camera),
        "camera": {
            "position_m": list(cam.position_m),
            "look_at_m": list(cam.look_at_m),
            "fovy_deg": cam.fovy_deg,
        },
        "objects": objects,
        "obstacle": obstacle,
        "layout": {
            "table_z_m": 0.0,
            "pick_zone_min_m": list(scene_cfg.pick_zone_min_m),
            "pick_zone_max_m": list(scene_cfg.pick_zone_max_m),
            "drop_zones_m": {k: list(v) for k, v in scene_cfg.drop_zones_m.items()},
            "rod_place_m": list(scene_cfg.rod_place_m),
        },
        "robot": {
            "model": settings.robot.model,
            "joints_rad": [float(v) for v in engine.state().q],
            "tcp_offset_m": settings.gripper.tcp_offset_m,
        },
        "labels": {
            "0": "table/background",
            **{str(o["label"]): o["name"] for o in objects},
            str(LABEL_OBSTACLE): "obstacle",
            str(LABEL_ROBOT): "robot",
        },
        "sim_time_s": engine.time_s,
    }


def write_sim_scene(
    seed: int,
    out_dir: str | Path,
    settings: Settings | None = None,
    *,
    frames: int = 1,
    noise: bool | None = None,
    settle_s: float = 0.3,
) -> Path:
    """Render a seeded scene to ``out_dir``; return the path of ``ground_truth.json``."""
    if not isinstance(seed, int) or seed < 0:
        raise InvalidInputError(f"seed must be a non-negative integer, got {seed!r}")
    if not isinstance(frames, int) or not 1 <= frames <= MAX_FRAMES:
        raise InvalidInputError(f"frames must be an integer within 1-{MAX_FRAMES}, got {frames!r}")
    if not (np.isfinite(settle_s) and 0 <= settle_s <= 60):
        raise InvalidInputError(f"settle_s must be within 0-60 s, got {settle_s!r}")
    settings = settings or load_settings()
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InvalidInputError(f"output path {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    engine = create_twin_engine(settings, seed)
    camera = TwinCamera(engine, seed=seed, noise=noise)
    try:
        if settle_s > 0:
            engine.settle(settle_s)
        truth = scene_truth(engine, settings)
        records = []
        for i in range(frames):
            frame, views = camera.capture_with_views()
            names = {
                "color": f"color_{i:03d}.png",
                "depth": f"depth_{i:03d}.png",
                "labels": f"labels_{i:03d}.png",
            }
            _write_png(out / names["color"], cv2.cvtColor(frame.color, cv2.COLOR_RGB2BGR))
            _write_png(out / names["depth"], frame.depth)
            _write_png(out / names["labels"], label_image(engine, views.geom_id))
            records.append({**names, "stamp_ns": frame.stamp_ns, "noise": camera.noise})
        truth["frames"] = records
        write_intrinsics(out, camera.intrinsics, DEPTH_SCALE)
        path = out / "ground_truth.json"
        path.write_text(json.dumps(truth, indent=2))
        return path
    finally:
        camera.close()
        engine.close()


def _write_png(path: Path, image: Array) -> None:
    if not cv2.imwrite(str(path), image):
        raise InvalidInputError(f"cannot write image {path}")


def load_sim_scene(directory: str | Path) -> SimSceneRecord:
    """Read a frame set written by :func:`write_sim_scene` back as RGBDFrames + labels + truth."""
    d = Path(directory)
    try:
        truth = json.loads((d / "ground_truth.json").read_text())
        intr_raw = json.loads((d / "intrinsics.json").read_text())
    except FileNotFoundError as exc:
        raise InvalidInputError(f"{d} is not a sim scene directory: {exc.filename} is missing") from exc
    intr = CameraIntrinsics(
        width=intr_raw["width"],
        height=intr_raw["height"],
        fx=intr_raw["fx"],
        fy=intr_raw["fy"],
        cx=intr_raw["cx"],
        cy=intr_raw["cy"],
        distortion=tuple(intr_raw.get("distortion", ())),
    ).validate()
    frames, labels = [], []
    for k, rec in enumerate(truth.get("frames", [])):
        color = cv2.imread(str(d / rec["color"]), cv2.IMREAD_COLOR)
        depth = cv2.imread(str(d / rec["depth"]), cv2.IMREAD_UNCHANGED)
        lab = cv2.imread(str(d / rec["labels"]), cv2.IMREAD_UNCHANGED)
        if color is None or depth is None or lab is None:
            raise InvalidInputError(f"frame {k} of {d} has a missing or unreadable image")
        frames.append(
            RGBDFrame(
                color=cv2.cvtColor(color, cv2.COLOR_BGR2RGB),
                depth=depth,
                intrinsics=intr,
                depth_scale=float(intr_raw["depth_scale"]),
                stamp_ns=int(rec["stamp_ns"]),
                frame_id="camera_color_optical_frame",
                seq=k + 1,
            ).validate()
        )
        labels.append(lab)
    return SimSceneRecord(frames=frames, labels=labels, truth=truth)
