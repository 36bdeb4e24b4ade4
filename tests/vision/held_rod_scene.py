"""A rod held upright in the jaws, ray-cast into a depth frame (the synthetic renderer's cylinder and box
tests): a leaning rod, the fingers across it, the table below."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.sensors import RGBDFrame
from services.vision.held_rod import HeldRodRegion
from services.vision.synthetic import _camera_rays, _hit_box, _hit_cylinder, d435_intrinsics, look_at_camera

GRASP = np.array([0.45, 0.05, 0.20])  # the jaws' centre, base frame
LENGTH, RADIUS = 0.20, 0.011
OFFSET = 0.04  # grasped this far above the rod's centre


@dataclass(frozen=True)
class HeldRodScene:
    frame: RGBDFrame
    T_base_camera: np.ndarray
    direction: np.ndarray  # the rod's axis, up


def held_rod_scene(
    tilt_deg: float,
    lean_azimuth_deg: float,
    noise_m: float = 0.0,
    seed: int = 0,
    camera_azimuth_deg: float = 200.0,
) -> HeldRodScene:
    intr = d435_intrinsics()
    T = look_at_camera(GRASP - [0.0, 0.0, 0.05], 0.8, 50.0, camera_azimuth_deg)
    lean = np.deg2rad(lean_azimuth_deg)
    tilt_axis = np.array([-np.sin(lean), np.cos(lean), 0.0])  # leans toward the azimuth
    R_rod = Rotation.from_rotvec(np.deg2rad(tilt_deg) * tilt_axis).as_matrix() @ np.array(
        [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]
    )  # rod frame: x along the rod, up
    direction = R_rod[:, 0]
    centre = GRASP - OFFSET * direction
    rays = _camera_rays(intr) @ T[:3, :3].T
    origin = T[:3, 3]
    t_rod, _ = _hit_cylinder(R_rod.T @ (origin - centre), rays @ R_rod, LENGTH, RADIUS)
    fingers = np.array([0.015, 0.03, 0.02])  # half: along the rod, the closing axis, the approach
    t_fingers, _ = _hit_box(R_rod.T @ (origin - GRASP), rays @ R_rod, fingers)
    with np.errstate(divide="ignore"):
        t_table = np.where(rays[..., 2] < 0, -origin[2] / rays[..., 2], np.inf)
    depth = np.minimum(np.minimum(t_rod, t_fingers), t_table)
    rng = np.random.default_rng(seed)
    depth = np.where(np.isfinite(depth), depth + rng.normal(0.0, noise_m, depth.shape), 0.0)
    z16 = np.clip(np.round(depth / 1e-4), 0, 65535).astype(np.uint16)
    color = np.full((intr.height, intr.width, 3), 128, dtype=np.uint8)
    return HeldRodScene(RGBDFrame(color, z16, intr, depth_scale=1e-4), T, direction)


def region(radius_m: float = RADIUS + 0.015) -> HeldRodRegion:
    reach = LENGTH / 2 + OFFSET + 0.015
    return HeldRodRegion(GRASP, np.array([0.0, 0.0, 1.0]), radius_m, -reach, reach, -0.023, 0.023)
