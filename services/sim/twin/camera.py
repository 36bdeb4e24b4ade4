"""The simulated RealSense D435i: aligned RGB + z16 depth rendered from the twin.

Implements the vision ``Camera`` protocol. Each capture copies a snapshot of the twin's state under
the engine's lock (microseconds) and renders it on the camera's own MjData, so physics is never
blocked by rendering. Depth comes from MuJoCo's depth pass (metric z along the optical axis, like
RealSense z16); the colour pass's depth would be biased. The segmentation pass tells the noise
model which pixels lie on hole-prone (black, shiny) objects and gives evaluation code its masks.

Reported intrinsics are the nominal ones: square pixels, fy = (H/2)/tan(fovy/2), principal point at
the image centre in pixel-index coordinates ((W−1)/2, (H−1)/2) — exact for an unvaried world. A
randomized world (``world.variation``) renders with its true focal length and principal point
(:func:`true_intrinsics`) and its own depth-noise level, hole share and highlight strength, while the
frames still report the nominal intrinsics, like a camera whose factory calibration is a little off.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import concurrent.futures
import dataclasses
import threading
from dataclasses import dataclass

import cv2
import mujoco
import numpy as np

from services.common.errors import CameraConnectionError
from services.common.sensors import CameraIntrinsics, RGBDFrame
from services.common.settings import TwinCameraSettings
from services.sim.twin import mjcf
from services.sim.twin.engine import TwinEngine, TwinSnapshot
from services.sim.twin.noise import (
    HIGHLIGHT_GAIN,
    DepthNoiseModel,
    apply_depth_noise,
    apply_rgb_noise,
    to_z16,
)
from services.sim.twin.randomization import Variation

Array = np.ndarray

DEPTH_SCALE = 0.001  # z16 in millimetres, the D435i default


@dataclass(frozen=True)
class CleanViews:
    """Noise-free render of one snapshot (evaluation: exact depth and per-pixel geom ids)."""

    color: Array  # (H, W, 3) uint8 RGB
    depth_m: Array  # (H, W) float32, 0 where nothing is within range
    geom_id: Array  # (H, W) int32, -1 where no geom
    time_s: float


HIGHLIGHT_BASE = 20  # about the black rod's diffuse brightness (0-255)


def boost_highlights(color: Array, hole_mask: Array, gain: float = HIGHLIGHT_GAIN) -> Array:
    """Colour with the specular highlights on shiny black objects brought to what a sensor records.

    Only pixels whose neighbours are all on the object are changed: its outline mixes in the table.
    """
    inner = cv2.erode(hole_mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    if not np.any(inner):
        return color
    px = color[inner].astype(np.float32)
    px = np.where(px > HIGHLIGHT_BASE, HIGHLIGHT_BASE + gain * (px - HIGHLIGHT_BASE), px)
    out = color.copy()
    out[inner] = np.clip(px, 0, 255).astype(np.uint8)
    return out


def twin_intrinsics(cam: TwinCameraSettings) -> CameraIntrinsics:
    fy = (cam.height / 2.0) / np.tan(np.radians(cam.fovy_deg) / 2.0)
    return CameraIntrinsics(
        width=cam.width,
        height=cam.height,
        fx=float(fy),
        fy=float(fy),
        cx=(cam.width - 1) / 2.0,
        cy=(cam.height - 1) / 2.0,
    ).validate()


def true_intrinsics(cam: TwinCameraSettings, variation: Variation) -> CameraIntrinsics:
    """The intrinsics a varied world renders with (the frames report :func:`twin_intrinsics`)."""
    nominal = twin_intrinsics(cam)
    if not variation.randomized:
        return nominal
    du, dv = variation.principal_offset_px
    return CameraIntrinsics(
        width=cam.width,
        height=cam.height,
        fx=nominal.fx * variation.focal_scale,
        fy=nominal.fy * variation.focal_scale,
        cx=nominal.cx + du,
        cy=nominal.cy + dv,
    ).validate()


class TwinCamera:
    """Renders the twin as a D435i would see it. ``noise=None`` follows the settings."""

    def __init__(
        self,
        engine: TwinEngine,
        seed: int = 0,
        noise: bool | None = None,
        settings: TwinCameraSettings | None = None,
    ):
        self._engine = engine
        self._model = engine.model
        self._cfg = settings or engine.world.twin.camera
        self._noise_on = self._cfg.noise if noise is None else noise
        self._noise = DepthNoiseModel.from_settings(self._cfg)
        self._highlight_gain = HIGHLIGHT_GAIN
        v = engine.world.variation
        if v.randomized and settings is None:  # this world's sensor and light
            self._noise = dataclasses.replace(
                self._noise, subpixel=v.depth_subpixel, hole_fraction=v.hole_fraction
            )
            self._highlight_gain = v.highlight_gain
        self._rng = np.random.default_rng(seed)
        self._intrinsics = twin_intrinsics(self._cfg)
        self._data = mujoco.MjData(self._model)
        self._renderer: mujoco.Renderer | None = None
        self._option = mujoco.MjvOption()
        self._camera_id = mujoco.mj_name2id(self._model, mujoco.mjtObj.mjOBJ_CAMERA, mjcf.CAMERA)
        self._lock = threading.Lock()
        self._gl_executor = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix="twin-camera-gl"
        )
        self._gl_owner: threading.Thread | None = None
        self._seq = 0
        self._closed = False
        w = engine.world
        hole_objects = set(self._cfg.hole_objects)
        self._hole_geom = np.array(
            [
                w.geom_object[g] >= 0 and w.scene.objects[w.geom_object[g]].name in hole_objects
                for g in range(self._model.ngeom)
            ]
            + [False]
        )  # index -1 (no geom) → False

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intrinsics

    @property
    def noise(self) -> bool:
        return self._noise_on

    def capture(self) -> RGBDFrame:
        frame, _ = self.capture_with_views()
        return frame

    @classmethod
    def ready(cls, engine: TwinEngine, seed: int = 0) -> TwinCamera:
        """A camera whose off-screen renderer is set up and holds the scene (one render, no frame
        taken), so the first capture someone waits for costs what any other does: a new world's camera
        took 0.3-0.45 s over its first frame, inside the DETECT of the eval's next trial."""
        camera = cls(engine, seed=seed)
        camera.render(engine.snapshot())
        return camera

    def capture_with_views(self) -> tuple[RGBDFrame, CleanViews]:
        """A frame (noise per settings) and the clean views it was made from (evaluation only)."""
        views = self.render(self._engine.snapshot())
        with self._lock:
            self._seq += 1
            seq = self._seq
            if self._noise_on:
                hole_mask = self._hole_geom[views.geom_id]
                depth_m = apply_depth_noise(views.depth_m, hole_mask, self._noise, self._rng)
                color = apply_rgb_noise(
                    boost_highlights(views.color, hole_mask, self._highlight_gain),
                    self._noise.rgb_sigma,
                    self._rng,
                )
            else:
                depth_m, color = views.depth_m, views.color
        frame = RGBDFrame(
            color=color,
            depth=to_z16(depth_m, DEPTH_SCALE),
            intrinsics=self._intrinsics,
            depth_scale=DEPTH_SCALE,
            stamp_ns=round(views.time_s * 1e9),
            frame_id="camera_color_optical_frame",
            seq=seq,
            meta={"source": "twin", "noise": self._noise_on},
        )
        return frame, views

    def render(self, snapshot: TwinSnapshot) -> CleanViews:
        """Colour, depth and segmentation passes of one snapshot, without noise.

        An EGL context is current on one thread only, so every GL call runs on this camera's
        own render thread, whichever thread asks for a frame."""
        if self._closed:
            raise CameraConnectionError("the twin camera is closed")
        if threading.current_thread() is not self._gl_thread():
            return self._gl_executor.submit(self.render, snapshot).result()
        with self._lock:
            if self._closed:
                raise CameraConnectionError("the twin camera is closed")
            r = self._ensure_renderer()
            d = self._data
            d.qpos[:] = snapshot.qpos
            d.qvel[:] = snapshot.qvel
            d.time = snapshot.time_s
            mujoco.mj_kinematics(self._model, d)
            mujoco.mj_camlight(self._model, d)
            r.update_scene(d, self._camera_id, self._option)
            color = r.render().copy()
            r.enable_depth_rendering()
            depth = r.render().astype(np.float32)
            r.disable_depth_rendering()
            r.enable_segmentation_rendering()
            seg = r.render()
            r.disable_segmentation_rendering()
        geom_id = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1).astype(np.int32)
        depth[(geom_id < 0) | (depth < self._cfg.min_depth_m) | (depth > self._cfg.max_depth_m)] = 0.0
        return CleanViews(color=color, depth_m=depth, geom_id=geom_id, time_s=snapshot.time_s)

    def _ensure_renderer(self) -> mujoco.Renderer:
        if self._renderer is None:
            try:
                self._renderer = mujoco.Renderer(self._model, height=self._cfg.height, width=self._cfg.width)
            except Exception as exc:  # GL backend missing or failing: name the cause
                raise CameraConnectionError(
                    f"cannot create the twin's off-screen renderer (MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}): "
                    f"{exc}"
                ) from exc
        return self._renderer

    def _gl_thread(self) -> threading.Thread:
        if self._gl_owner is None:
            self._gl_owner = self._gl_executor.submit(threading.current_thread).result()
        return self._gl_owner

    def close(self) -> None:
        def release() -> None:
            with self._lock:
                self._closed = True
                if self._renderer is not None:
                    self._renderer.close()
                    self._renderer = None

        if self._gl_owner is None or threading.current_thread() is self._gl_owner:
            release()
        else:
            self._gl_executor.submit(release).result()
        self._gl_executor.shutdown(wait=False)


def create_twin_camera(engine: TwinEngine, seed: int = 0, noise: bool | None = None) -> TwinCamera:
    return TwinCamera(engine, seed=seed, noise=noise)
