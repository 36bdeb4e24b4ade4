"""Seeded random scenes for the synthetic ray caster (``synthetic``): camera poses, the rod, cubes and an
obstacle placed without overlap, within ranges that cover what a real cell shows."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np

from services.common.sensors import CameraIntrinsics
from services.vision.synthetic import (
    DARK_MAT_RGB,
    LIGHT_TABLE_RGB,
    Array,
    BoxSpec,
    NoiseModel,
    RodSpec,
    SyntheticScene,
    d435_intrinsics,
    look_at_camera,
    render_scene,
)

_Spec = TypeVar("_Spec", RodSpec, BoxSpec)  # what scene placement puts on the table


@dataclass(frozen=True)
class SceneRanges:
    distance_m: tuple[float, float] = (0.5, 0.9)
    pitch_deg: tuple[float, float] = (50.0, 60.0)
    azimuth_deg: tuple[float, float] = (-15.0, 15.0)
    target_xy: tuple[tuple[float, float], tuple[float, float]] = ((0.35, 0.50), (-0.10, 0.10))
    cube_size_m: float = 0.05
    obstacle_size_m: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] = (
        (0.12, 0.20),
        (0.10, 0.16),
        (0.06, 0.12),
    )
    margin_px: int = 12
    min_visible_fraction: float = 0.9


def random_scene(
    seed: int,
    *,
    n_rods: int = 1,
    cube_colors: tuple[str, ...] = (),
    obstacle: bool = False,
    dark_mat: bool = False,
    intrinsics: CameraIntrinsics | None = None,
    ranges: SceneRanges | None = None,
    rod_length_m: float = 0.200,
    rod_radius_m: float = 0.011,
) -> SyntheticScene:
    """A random, fully visible, non-overlapping layout in front of a randomly placed camera.

    Objects are placed on the table inside the camera's view (projected corners at least
    ``margin_px`` inside the image), at least 4 cm apart, and re-drawn until each is at least
    ``min_visible_fraction`` unoccluded.
    """
    rng = np.random.default_rng(seed)
    ranges = ranges or SceneRanges()
    intr = intrinsics or d435_intrinsics()
    for _attempt in range(200):
        target = np.array([rng.uniform(*ranges.target_xy[0]), rng.uniform(*ranges.target_xy[1]), 0.0])
        dist = rng.uniform(*ranges.distance_m)
        T = look_at_camera(target, dist, rng.uniform(*ranges.pitch_deg), rng.uniform(*ranges.azimuth_deg))
        scene = _place_objects(
            rng, T, intr, target, dist, n_rods, cube_colors, obstacle, ranges, rod_length_m, rod_radius_m
        )
        if scene is None:
            continue
        scene = replace(scene, table_rgb=DARK_MAT_RGB if dark_mat else LIGHT_TABLE_RGB)
        if not (scene.rods or scene.boxes):
            return scene
        check = render_scene(scene, NoiseModel.off())
        if all(f >= ranges.min_visible_fraction for f in check.visible_fraction.values()):
            return scene
    raise RuntimeError(f"could not lay out a visible scene for seed {seed}")


def _place_objects(
    rng: np.random.Generator,
    T_base_camera: Array,
    intr: CameraIntrinsics,
    target: Array,
    dist: float,
    n_rods: int,
    cube_colors: tuple[str, ...],
    obstacle: bool,
    ranges: SceneRanges,
    rod_length: float,
    rod_radius: float,
) -> SyntheticScene | None:
    T_camera_base = np.linalg.inv(T_base_camera)
    spread = 0.30 * dist  # the visible table patch grows with distance
    placed: list[tuple[Array, float]] = []  # (xy, footprint radius)
    rods: list[RodSpec] = []
    boxes: list[BoxSpec] = []
    obstacle_idx: tuple[int, ...] = ()

    def in_view(corners: Array) -> bool:
        pc = (T_camera_base[:3, :3] @ corners.T).T + T_camera_base[:3, 3]
        if np.any(pc[:, 2] <= 0.05):
            return False
        u = intr.fx * pc[:, 0] / pc[:, 2] + intr.cx
        v = intr.fy * pc[:, 1] / pc[:, 2] + intr.cy
        m = ranges.margin_px
        return bool(np.all((u >= m) & (u <= intr.width - m) & (v >= m) & (v <= intr.height - m)))

    def try_place(
        radius: float, make: Callable[[Array], tuple[_Spec, Array]], tries: int = 60
    ) -> _Spec | None:
        for _ in range(tries):
            xy = target[:2] + rng.uniform(-spread, spread, 2) * np.array([0.8, 1.0])
            if any(np.linalg.norm(xy - q) < radius + rq + 0.04 for q, rq in placed):
                continue
            spec, corners = make(xy)
            if in_view(corners):
                placed.append((xy, radius))
                return spec
        return None

    if obstacle:
        (sx, sx_hi), (sy, sy_hi), (sz, sz_hi) = ranges.obstacle_size_m
        size = (rng.uniform(sx, sx_hi), rng.uniform(sy, sy_hi), rng.uniform(sz, sz_hi))

        def make_obstacle(xy: Array) -> tuple[BoxSpec, Array]:
            b = BoxSpec((xy[0], xy[1], size[2] / 2), size, rng.uniform(-np.pi, np.pi), "blue")
            return b, b.corners()

        obstacle_box = try_place(0.5 * float(np.hypot(size[0], size[1])), make_obstacle)
        if obstacle_box is None:
            return None
        boxes.append(obstacle_box)
        obstacle_idx = (0,)
    for _ in range(n_rods):

        def make_rod(xy: Array) -> tuple[RodSpec, Array]:
            r = RodSpec((xy[0], xy[1], rod_radius), rng.uniform(-np.pi, np.pi), rod_length, rod_radius)
            ends = np.array([r.center + s * r.axis * rod_length / 2 for s in (-1, 1)])
            corners = np.concatenate([ends + [0, 0, rod_radius], ends - [0, 0, rod_radius]])
            return r, corners

        rod = try_place(rod_length / 2, make_rod)
        if rod is None:
            return None
        rods.append(rod)
    s = ranges.cube_size_m
    for colour in cube_colors:

        def make_cube(xy: Array, colour: str = colour) -> tuple[BoxSpec, Array]:
            b = BoxSpec((xy[0], xy[1], s / 2), (s, s, s), rng.uniform(-np.pi, np.pi), colour)
            return b, b.corners()

        cube = try_place(s * 0.75, make_cube)
        if cube is None:
            return None
        boxes.append(cube)
    return SyntheticScene(
        T_base_camera=T_base_camera,
        intrinsics=intr,
        rods=tuple(rods),
        boxes=tuple(boxes),
        obstacle_indices=obstacle_idx,
    )


# --- calibration board views --------------------------------------------------------------------
