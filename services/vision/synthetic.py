"""Synthetic RGB-D scenes with ground truth: a small vectorised ray caster.

Test and benchmark data for the vision cores until (and beside) the physics
twin: a table (light or dark mat) with a black rod (cylinder with flat caps),
coloured cubes and an obstacle box, seen by a D435i-like pinhole camera.
Every pixel's ray is intersected analytically with every object (numpy, no
per-pixel loops); the nearest hit wins. A seeded noise model adds what a real
D435i does to depth: range-dependent noise (σ ∝ z², plus a spatially
correlated part), holes on the black metal, flying pixels at depth edges,
random dropout, millimetre quantisation; and RGB noise.

Frames: the base frame has z up with the table top at z = 0; ``T_base_camera``
maps camera points to base points (camera z forward, x right, y down).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from services.common.frames import make_transform
from services.common.sensors import CameraIntrinsics, RGBDFrame

Array = np.ndarray

COLORS_RGB: dict[str, tuple[int, int, int]] = {
    "red": (200, 30, 35),
    "green": (40, 170, 60),
    "blue": (35, 70, 200),
    "black": (28, 28, 30),
    "yellow": (215, 190, 40),
    "grey": (128, 128, 128),
    "white": (235, 235, 232),
}
LIGHT_TABLE_RGB = (196, 186, 166)
DARK_MAT_RGB = (52, 54, 58)
FLOOR_RGB = (110, 105, 100)
ROD_RGB = (30, 30, 33)

# Object ids in the label image: 0 = nothing/floor, 1 = table, objects from 10 on.
LABEL_NONE, LABEL_TABLE, LABEL_FIRST_OBJECT = 0, 1, 10


def d435_intrinsics(width: int = 640, height: int = 480) -> CameraIntrinsics:
    """D435i colour-stream intrinsics: fx = fy ≈ 617 px at 640×480 (4:3 crop), ≈ 925 px at 1280×720."""
    f = 617.0 * (width / 640.0) if width * 3 == height * 4 else 925.0 * (width / 1280.0)
    return CameraIntrinsics(width=width, height=height, fx=f, fy=f, cx=width / 2.0, cy=height / 2.0)


def look_at_camera(target: Array, distance_m: float, pitch_deg: float, azimuth_deg: float = 0.0) -> Array:
    """T_base_camera of a camera ``distance_m`` from ``target``, pitched down, optical axis through it.

    ``azimuth_deg`` is the horizontal direction from the target to the camera (0 = along +x).
    """
    target = np.asarray(target, dtype=float)
    pitch, az = np.deg2rad(pitch_deg), np.deg2rad(azimuth_deg)
    offset = distance_m * np.array([np.cos(pitch) * np.cos(az), np.cos(pitch) * np.sin(az), np.sin(pitch)])
    position = target + offset
    z_cam = -offset / np.linalg.norm(offset)
    x_cam = np.cross(z_cam, [0.0, 0.0, 1.0])
    x_cam /= np.linalg.norm(x_cam)
    y_cam = np.cross(z_cam, x_cam)
    return make_transform(np.column_stack([x_cam, y_cam, z_cam]), position)


def yaw_matrix(yaw: float) -> Array:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class RodSpec:
    """A cylinder lying on the table: centre (base frame), yaw of its axis about z."""

    center: tuple[float, float, float]
    yaw: float
    length_m: float = 0.200
    radius_m: float = 0.011

    @property
    def axis(self) -> Array:
        return np.array([np.cos(self.yaw), np.sin(self.yaw), 0.0])


@dataclass(frozen=True)
class BoxSpec:
    """A box resting on the table: centre (base frame), full size, yaw, colour name."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float
    color: str

    def corners(self) -> Array:
        half = np.asarray(self.size) / 2.0
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        return (yaw_matrix(self.yaw) @ (signs * half).T).T + np.asarray(self.center)


@dataclass(frozen=True)
class NoiseModel:
    """D435i-like degradations. σ_depth = depth_sigma_per_m2 · z² + a correlated part."""

    enabled: bool = True
    depth_sigma_per_m2: float = 0.004  # 2 mm at 0.7 m, 3.2 mm at 0.9 m
    correlated_sigma_m: float = 0.0006
    rod_hole_fraction: float = 0.35  # share of rod pixels without depth
    dropout: float = 0.005  # random missing depth everywhere
    flying_pixel_prob: float = 0.5  # at depth edges
    rgb_sigma: float = 3.0
    rod_specular: float = 45.0  # peak added brightness of the highlight on the black metal
    # A specular stripe along the tube as black metal under cell lights shows (the hard scene set):
    # peak brightness (0 = none, 255 = saturated), its angular half-width on the tube, where it sits
    # (degrees from the tube's camera-facing line) and how much it fades from one end to the other.
    rod_stripe_value: float = 0.0
    rod_stripe_halfwidth_deg: float = 12.0
    rod_stripe_offset_deg: float = 0.0
    rod_stripe_taper: float = 0.0

    @classmethod
    def off(cls) -> NoiseModel:
        return cls(enabled=False, rod_specular=0.0, rgb_sigma=0.0)


@dataclass(frozen=True)
class SyntheticScene:
    T_base_camera: Array
    intrinsics: CameraIntrinsics
    rods: tuple[RodSpec, ...] = ()
    boxes: tuple[BoxSpec, ...] = ()  # cubes and obstacles
    table_rgb: tuple[int, int, int] = LIGHT_TABLE_RGB
    table_min: tuple[float, float] = (-0.3, -0.8)
    table_max: tuple[float, float] = (1.6, 0.8)
    floor_z: float = -0.75
    obstacle_indices: tuple[int, ...] = ()  # which boxes are obstacles

    @property
    def cubes(self) -> list[BoxSpec]:
        return [b for i, b in enumerate(self.boxes) if i not in self.obstacle_indices]

    @property
    def obstacles(self) -> list[BoxSpec]:
        return [b for i, b in enumerate(self.boxes) if i in self.obstacle_indices]


@dataclass
class RenderedScene:
    frame: RGBDFrame
    scene: SyntheticScene
    labels: Array  # (H, W) int32: 0 floor/none, 1 table, 10 + k object k (rods first, then boxes)
    depth_true_m: Array  # noiseless depth (0 where nothing was hit)
    visible_fraction: dict[int, float] = field(default_factory=dict)


# --- ray casting ---------------------------------------------------------------------------------
def _camera_rays(intr: CameraIntrinsics) -> Array:
    """(H, W, 3) rays through pixel centres with z = 1, so the hit distance t is the depth."""
    u = (np.arange(intr.width, dtype=float) - intr.cx) / intr.fx
    v = (np.arange(intr.height, dtype=float) - intr.cy) / intr.fy
    rays = np.empty((intr.height, intr.width, 3))
    rays[..., 0] = u[None, :]
    rays[..., 1] = v[:, None]
    rays[..., 2] = 1.0
    return rays


def _roi(
    corners_base: Array, T_camera_base: Array, intr: CameraIntrinsics, pad: int = 3
) -> tuple[slice, slice]:
    """Image rectangle that contains the projection of these corners (whole image if any is behind)."""
    pc = (T_camera_base[:3, :3] @ corners_base.T).T + T_camera_base[:3, 3]
    if np.any(pc[:, 2] <= 1e-3):
        return slice(0, intr.height), slice(0, intr.width)
    u = intr.fx * pc[:, 0] / pc[:, 2] + intr.cx
    v = intr.fy * pc[:, 1] / pc[:, 2] + intr.cy
    u0, u1 = (
        int(np.clip(np.floor(u.min()) - pad, 0, intr.width)),
        int(np.clip(np.ceil(u.max()) + pad, 0, intr.width)),
    )
    v0, v1 = (
        int(np.clip(np.floor(v.min()) - pad, 0, intr.height)),
        int(np.clip(np.ceil(v.max()) + pad, 0, intr.height)),
    )
    return slice(v0, v1), slice(u0, u1)


def _hit_cylinder(o: Array, d: Array, length: float, r: float) -> tuple[Array, Array]:
    """Rays (o, d) in the rod frame (axis = x) → (t, normal); t = inf where missed."""
    half = length / 2.0
    t = np.full(d.shape[:-1], np.inf)
    normal = np.zeros(d.shape)
    a = d[..., 1] ** 2 + d[..., 2] ** 2
    b = 2.0 * (o[1] * d[..., 1] + o[2] * d[..., 2])
    c = o[1] ** 2 + o[2] ** 2 - r * r
    disc = b * b - 4 * a * c
    ok = (disc >= 0) & (a > 1e-12)
    with np.errstate(invalid="ignore", divide="ignore"):
        ts = (-b - np.sqrt(np.where(ok, disc, 0.0))) / (2 * np.where(ok, a, 1.0))
    x_side = o[0] + ts * d[..., 0]
    side = ok & (ts > 0) & (np.abs(x_side) <= half)
    t = np.where(side, ts, t)
    p_side = o + ts[..., None] * d
    normal = np.where(
        side[..., None], np.stack([np.zeros_like(ts), p_side[..., 1], p_side[..., 2]], -1) / r, normal
    )
    for sign in (-1.0, 1.0):
        with np.errstate(invalid="ignore", divide="ignore"):
            tc = (sign * half - o[0]) / d[..., 0]
        pc = o + tc[..., None] * d
        cap = np.isfinite(tc) & (tc > 0) & (pc[..., 1] ** 2 + pc[..., 2] ** 2 <= r * r) & (tc < t)
        t = np.where(cap, tc, t)
        normal = np.where(cap[..., None], np.array([sign, 0.0, 0.0]), normal)
    return t, normal


def _hit_box(o: Array, d: Array, half: Array) -> tuple[Array, Array]:
    """Slab test in the box frame → (t, normal); t = inf where missed."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1 = (-half - o) * inv
        t2 = (half - o) * inv
    tmin = np.minimum(t1, t2)
    tmax = np.maximum(t1, t2)
    tmin = np.where(np.isnan(tmin), -np.inf, tmin)
    tmax = np.where(np.isnan(tmax), np.inf, tmax)
    t_near = tmin.max(axis=-1)
    t_far = tmax.min(axis=-1)
    hit = (t_near <= t_far) & (t_near > 0)
    t = np.where(hit, t_near, np.inf)
    axis = tmin.argmax(axis=-1)
    normal = np.zeros(d.shape)
    idx = np.indices(axis.shape)
    normal[(*idx, axis)] = -np.sign(np.take_along_axis(d, axis[..., None], -1)[..., 0])
    return t, normal


def render_scene(scene: SyntheticScene, noise: NoiseModel | None = None, seed: int = 0) -> RenderedScene:
    """Ray-cast the scene into an aligned RGB-D frame (uint8 RGB, uint16 mm depth) with ground truth."""
    noise = noise or NoiseModel()
    rng = np.random.default_rng(seed)
    intr = scene.intrinsics
    T = np.asarray(scene.T_base_camera, dtype=float)
    R, origin = T[:3, :3], T[:3, 3]
    T_camera_base = np.linalg.inv(T)
    rays_cam = _camera_rays(intr)
    rays = rays_cam @ R.T  # base-frame directions, still scaled so t = depth

    H, W = intr.height, intr.width
    depth = np.full((H, W), np.inf)
    labels = np.zeros((H, W), dtype=np.int32)
    albedo = np.zeros((H, W, 3))
    normals = np.zeros((H, W, 3))
    albedo[:] = FLOOR_RGB
    normals[..., 2] = 1.0

    # Floor and table (horizontal planes).
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = (scene.floor_z - origin[2]) / rays[..., 2]
        t_table = (0.0 - origin[2]) / rays[..., 2]
    t_floor = np.where(t_floor > 0, t_floor, np.inf)
    depth = np.minimum(depth, t_floor)
    p_table = origin + t_table[..., None] * rays
    on_table = (
        (t_table > 0)
        & (p_table[..., 0] >= scene.table_min[0])
        & (p_table[..., 0] <= scene.table_max[0])
        & (p_table[..., 1] >= scene.table_min[1])
        & (p_table[..., 1] <= scene.table_max[1])
    )
    depth = np.where(on_table, t_table, depth)
    labels[on_table] = LABEL_TABLE
    albedo[on_table] = scene.table_rgb
    table_depth = np.where(on_table, t_table, np.inf)

    visible_alone: dict[int, int] = {}
    stripe = np.zeros((H, W))  # 0..1 weight of the specular stripe on rod pixels
    rod_ids = []
    objects: list[tuple[int, str, object]] = [
        (LABEL_FIRST_OBJECT + i, "rod", r) for i, r in enumerate(scene.rods)
    ]
    objects += [(LABEL_FIRST_OBJECT + len(scene.rods) + i, "box", b) for i, b in enumerate(scene.boxes)]
    for obj_id, kind, spec in objects:
        if kind == "rod":
            assert isinstance(spec, RodSpec)
            Rw = yaw_matrix(spec.yaw)
            half_ext = np.array([spec.length_m / 2, spec.radius_m, spec.radius_m])
            colour = ROD_RGB
            rod_ids.append(obj_id)
        else:
            assert isinstance(spec, BoxSpec)
            Rw = yaw_matrix(spec.yaw)
            half_ext = np.asarray(spec.size) / 2.0
            colour = COLORS_RGB[spec.color]
        center = np.asarray(spec.center, dtype=float)
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        corners = (Rw @ (signs * half_ext).T).T + center
        rs, cs = _roi(corners, T_camera_base, intr)
        d_local = rays[rs, cs] @ Rw  # R^T d for row vectors
        o_local = Rw.T @ (origin - center)
        if isinstance(spec, RodSpec):
            t, n_local = _hit_cylinder(o_local, d_local, spec.length_m, spec.radius_m)
        else:
            t, n_local = _hit_box(o_local, d_local, half_ext)
        visible_alone[obj_id] = int(np.count_nonzero(t < table_depth[rs, cs]))
        closer = t < depth[rs, cs]
        depth[rs, cs] = np.where(closer, t, depth[rs, cs])
        labels[rs, cs] = np.where(closer, obj_id, labels[rs, cs])
        albedo[rs, cs] = np.where(closer[..., None], np.asarray(colour, dtype=float), albedo[rs, cs])
        normals[rs, cs] = np.where(closer[..., None], n_local @ Rw.T, normals[rs, cs])
        if isinstance(spec, RodSpec) and noise.rod_stripe_value > 0:
            stripe[rs, cs] = np.where(closer, _stripe_weight(o_local, d_local, t, n_local, spec, noise), 0.0)

    visible = {k: float(np.count_nonzero(labels == k)) / v if v else 0.0 for k, v in visible_alone.items()}

    # Shading: ambient + Lambert from an overhead light, plus a specular streak on the rod.
    light = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
    lambert = np.clip(normals @ light, 0.0, 1.0)
    rgb = albedo * (0.55 + 0.45 * lambert)[..., None]
    is_rod = np.isin(labels, rod_ids) if rod_ids else np.zeros((H, W), bool)
    if noise.rod_specular > 0 and rod_ids:
        view = -rays / np.linalg.norm(rays, axis=-1, keepdims=True)
        half_vec = view + light
        half_vec /= np.linalg.norm(half_vec, axis=-1, keepdims=True)
        spec_term = np.clip(np.sum(normals * half_vec, axis=-1), 0.0, 1.0) ** 40
        rgb += (noise.rod_specular * spec_term * is_rod)[..., None]
    if noise.rod_stripe_value > 0:
        rgb += (noise.rod_stripe_value - rgb) * stripe[..., None]
    if noise.enabled and noise.rgb_sigma > 0:
        rgb += rng.normal(0.0, noise.rgb_sigma, rgb.shape)
    color = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)

    depth_true = np.where(np.isfinite(depth), depth, 0.0)
    depth_m = depth_true.copy()
    valid = depth_true > 0
    if noise.enabled:
        depth_m = _degrade_depth(depth_m, valid, is_rod, noise, rng)
    depth_mm = np.clip(np.rint(depth_m * 1000.0), 0, 65535).astype(np.uint16)
    frame = RGBDFrame(color=color, depth=depth_mm, intrinsics=intr, depth_scale=0.001, frame_id="camera")
    return RenderedScene(
        frame=frame, scene=scene, labels=labels, depth_true_m=depth_true, visible_fraction=visible
    )


def _stripe_weight(o: Array, d: Array, t: Array, n: Array, rod: RodSpec, noise: NoiseModel) -> Array:
    """Stripe weight of rod pixels (rod frame: axis = x): a Gaussian in the angle about the axis,
    centred ``rod_stripe_offset_deg`` from the line facing the camera, fading along the axis."""
    facing = np.arctan2(o[1], o[2])  # angle about x of the camera seen from the axis
    centre = facing + np.deg2rad(noise.rod_stripe_offset_deg)
    phi = np.arctan2(n[..., 1], n[..., 2])
    dphi = np.angle(np.exp(1j * (phi - centre)))
    w = np.exp(-0.5 * (dphi / np.deg2rad(noise.rod_stripe_halfwidth_deg)) ** 2)
    with np.errstate(invalid="ignore"):
        x = o[0] + np.where(np.isfinite(t), t, 0.0) * d[..., 0]
    along = np.clip(x / rod.length_m + 0.5, 0.0, 1.0)
    w = w * (1.0 - noise.rod_stripe_taper * along)
    side = np.abs(n[..., 0]) < 0.5  # the caps carry no stripe
    return np.where(np.isfinite(t) & side, w, 0.0)


def _smooth_field(rng: np.random.Generator, shape: tuple[int, int], cell_px: int) -> Array:
    """Zero-mean, unit-σ spatially correlated noise with features about ``cell_px`` wide."""
    h, w = max(2, shape[0] // cell_px + 2), max(2, shape[1] // cell_px + 2)
    coarse = rng.normal(0.0, 1.0, (h, w)).astype(np.float32)
    fine = cv2.resize(coarse, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC).astype(float)
    return (fine - fine.mean()) / (fine.std() + 1e-12)


def _degrade_depth(
    depth_m: Array, valid: Array, is_rod: Array, noise: NoiseModel, rng: np.random.Generator
) -> Array:
    shape = depth_m.shape
    z = depth_m
    out = z + rng.normal(0.0, 1.0, shape) * noise.depth_sigma_per_m2 * z * z
    out += _smooth_field(rng, shape, 40) * noise.correlated_sigma_m
    # Flying pixels: at a depth step, a pixel takes a value between the two surfaces.
    zf = np.where(valid, z, 0).astype(np.float32)
    kernel = np.ones((3, 3), np.uint8)
    z_max = cv2.dilate(zf, kernel)
    z_min = cv2.erode(np.where(valid, zf, np.float32(1e6)), kernel)
    edge = valid & (z_max - z_min > 0.02) & (z_min < 1e5)
    flying = edge & (rng.random(shape) < noise.flying_pixel_prob)
    mix = rng.random(shape)
    out = np.where(flying, z_min + mix * (z_max - z_min), out)
    # Holes on the black metal: blobs plus scattered pixels, about rod_hole_fraction of the rod.
    if noise.rod_hole_fraction > 0 and np.any(is_rod):
        blob = _smooth_field(rng, shape, 6)
        thresh = (
            np.quantile(blob[is_rod], 1.0 - 0.8 * noise.rod_hole_fraction)
            if noise.rod_hole_fraction < 1
            else -np.inf
        )
        holes = is_rod & ((blob >= thresh) | (rng.random(shape) < 0.2 * noise.rod_hole_fraction))
        out = np.where(holes, 0.0, out)
    out = np.where(rng.random(shape) < noise.dropout, 0.0, out)
    return np.where(valid, np.maximum(out, 0.0), 0.0)


# --- random scenes ---------------------------------------------------------------------------------
def render_planar_target(
    board_image: Array,
    board_size_m: tuple[float, float],
    T_camera_board: Array,
    intrinsics: CameraIntrinsics,
    background: int = 90,
    blur_sigma: float = 0.6,
    noise_sigma: float = 2.0,
    seed: int = 0,
) -> Array:
    """Grey image of a flat printed target seen by the camera (for ChArUco tests).

    The board image covers ``board_size_m`` with its top-left at the board frame's origin, x to
    the right along image columns and y down along rows (the OpenCV board convention), z into the board.
    """
    h_px, w_px = board_image.shape[:2]
    sx, sy = board_size_m[0] / w_px, board_size_m[1] / h_px
    # board pixel (c, r) → board point (c·sx, r·sy, 0); camera pixel ~ K [r1 r2 t] [x y 1]^T
    R, t = T_camera_board[:3, :3], T_camera_board[:3, 3]
    H = intrinsics.K @ np.column_stack([R[:, 0], R[:, 1], t]) @ np.diag([sx, sy, 1.0])
    # board image pixel centres sit at (c + 0.5) in continuous coordinates
    H = H @ np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1.0]])
    # Render at 3x and area-average down: anti-aliased edges like a real lens, not jagged ones.
    ss = 3
    S = np.array(
        [[ss, 0, (ss - 1) / 2], [0, ss, (ss - 1) / 2], [0, 0, 1.0]]
    )  # output px centre → fine px centre
    H_fine = S @ H
    white = np.full_like(board_image, 255)
    size = (intrinsics.width * ss, intrinsics.height * ss)
    warped = cv2.warpPerspective(board_image, H_fine, size, flags=cv2.INTER_LINEAR, borderValue=0)
    cover = cv2.warpPerspective(white, H_fine, size, flags=cv2.INTER_LINEAR, borderValue=0).astype(np.float32)
    fine = (cover / 255.0) * warped.astype(np.float32) + (1.0 - cover / 255.0) * background
    img = cv2.resize(fine, (intrinsics.width, intrinsics.height), interpolation=cv2.INTER_AREA).astype(float)
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
    if noise_sigma > 0:
        img += np.random.default_rng(seed).normal(0.0, noise_sigma, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
