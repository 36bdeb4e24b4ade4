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
    RenderedScene,
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


# --- the hard scene set (issue 15) -----------------------------------------------------------------
HARD_OBSTACLE_COLORS = ("grey", "white", "black", "blue")
HARD_CUBE_COLORS = ("red", "green", "blue", "black", "yellow")
ROBOT_BASE_CLEAR_M = 0.16  # vision's robot_base_radius_m (0.13) plus a margin: nothing stands there
MAX_CUT_CUBE_DEPTH_M = 1.3  # a cube cut by the image edge still lies in vision's depth range (≤ 1.5 m)


@dataclass(frozen=True)
class HardCase:
    """One scene of the hard set with the degradations it was drawn with (the ground truth is the scene)."""

    seed: int
    scene: SyntheticScene
    noise: NoiseModel
    highlight_value: float  # peak brightness of the stripe on the rod (0 = none)
    dropout: float  # share of rod pixels without depth
    neighbour_gap_m: float | None  # free gap between the rod and a black neighbour beside it
    cut_boxes: tuple[int, ...]  # indices (in scene.boxes) of cubes cut by the image edge

    @property
    def partial_cubes(self) -> int:
        return len(self.cut_boxes)

    @property
    def has_rod(self) -> bool:
        return bool(self.scene.rods)

    def render(self) -> RenderedScene:
        return render_scene(self.scene, self.noise, seed=self.seed)


def hard_case(seed: int, width: int = 640, height: int = 480) -> HardCase:
    """A seeded scene of the hard set: what black metal in a real cell shows, in ranges a cell covers.

    Camera 0.6–1.0 m from the table at 45–75°; the rod (7 scenes in 8) with a specular stripe from none
    to saturated and 0–90 % of its depth missing in blobs; a black neighbour 10–40 mm beside it (3 in 5);
    grey/white/black/blue obstacles, cubes of five colours, some cut by the image edge.
    """
    rng = np.random.default_rng(seed)
    intr = d435_intrinsics(width, height)
    # Visibility is checked on a half-size render: same view, a quarter of the cost.
    check_intr = d435_intrinsics(width // 2, height // 2)
    has_rod = seed % 8 != 7
    highlight = float(rng.choice([0.0, 255.0, rng.uniform(100.0, 255.0)], p=[0.15, 0.15, 0.7]))
    noise = NoiseModel(
        rod_hole_fraction=float(rng.uniform(0.0, 0.9)),
        rod_stripe_value=highlight,
        rod_stripe_halfwidth_deg=float(rng.uniform(5.0, 18.0)),
        rod_stripe_offset_deg=float(rng.uniform(-35.0, 35.0)),
        rod_stripe_taper=float(rng.choice([0.0, rng.uniform(0.0, 1.0)])),
    )
    dark_mat = rng.random() < 0.25
    want_neighbour = rng.random() < 0.6
    n_obstacles = int(rng.integers(0, 3))
    n_cubes = int(rng.integers(0, 4))
    want_partial = rng.random() < 0.4
    for _attempt in range(300):
        target = np.array([rng.uniform(0.35, 0.5), rng.uniform(-0.1, 0.1), 0.0])
        dist = rng.uniform(0.6, 1.0)
        T = look_at_camera(target, dist, rng.uniform(45.0, 75.0), rng.uniform(-20.0, 20.0))
        layout = _hard_layout(
            rng, T, intr, target, dist, has_rod, want_neighbour, n_obstacles, n_cubes, want_partial
        )
        if layout is None:
            continue
        rods, boxes, obstacle_idx, gap, cut = layout
        scene = SyntheticScene(
            T_base_camera=T,
            intrinsics=intr,
            rods=rods,
            boxes=boxes,
            obstacle_indices=obstacle_idx,
            table_rgb=DARK_MAT_RGB if dark_mat else LIGHT_TABLE_RGB,
        )
        if rods:
            check = render_scene(replace(scene, intrinsics=check_intr), NoiseModel.off())
            if check.visible_fraction[0 + 10] < 0.9:  # the rod is label 10 (rods first)
                continue
        return HardCase(seed, scene, noise, highlight if rods else 0.0, noise.rod_hole_fraction, gap, cut)
    raise RuntimeError(f"could not lay out a hard scene for seed {seed}")


def _project_corners(T_camera_base: Array, intr: CameraIntrinsics, corners: Array) -> Array | None:
    pc = (T_camera_base[:3, :3] @ corners.T).T + T_camera_base[:3, 3]
    if np.any(pc[:, 2] <= 0.05):
        return None
    return np.column_stack([intr.fx * pc[:, 0] / pc[:, 2] + intr.cx, intr.fy * pc[:, 1] / pc[:, 2] + intr.cy])


def _hard_layout(
    rng: np.random.Generator,
    T_base_camera: Array,
    intr: CameraIntrinsics,
    target: Array,
    dist: float,
    has_rod: bool,
    want_neighbour: bool,
    n_obstacles: int,
    n_cubes: int,
    want_partial: bool,
) -> tuple[tuple[RodSpec, ...], tuple[BoxSpec, ...], tuple[int, ...], float | None, tuple[int, ...]] | None:
    T_camera_base = np.linalg.inv(T_base_camera)
    spread = 0.30 * dist
    placed: list[tuple[Array, float]] = []
    margin = 12 * intr.width / 640

    def inside(corners: Array) -> bool:
        uv = _project_corners(T_camera_base, intr, corners)
        return uv is not None and bool(
            np.all((uv[:, 0] >= margin) & (uv[:, 0] <= intr.width - margin))
            and np.all((uv[:, 1] >= margin) & (uv[:, 1] <= intr.height - margin))
        )

    def straddles(corners: Array) -> bool:
        """Partly in the image, partly out (cut by its edge), more than a quarter in, within working range."""
        uv = _project_corners(T_camera_base, intr, corners)
        depth = (T_camera_base[2, :3] @ corners.T) + T_camera_base[2, 3]
        if uv is None or depth.max() > MAX_CUT_CUBE_DEPTH_M:
            return False
        ins = (uv[:, 0] >= 0) & (uv[:, 0] < intr.width) & (uv[:, 1] >= 0) & (uv[:, 1] < intr.height)
        return 3 <= int(np.count_nonzero(ins)) <= 6

    def off_robot(corners: Array) -> bool:
        """Clear of the arm's own base (vision leaves that cylinder out: it is the robot)."""
        return bool(np.all(np.hypot(corners[:, 0], corners[:, 1]) >= ROBOT_BASE_CLEAR_M))

    def free(xy: Array, radius: float) -> bool:
        return all(np.linalg.norm(xy - q) >= radius + rq + 0.04 for q, rq in placed)

    rods: list[RodSpec] = []
    boxes: list[BoxSpec] = []
    gap: float | None = None
    r, L = 0.011, 0.200
    if has_rod:
        for _ in range(60):
            xy = target[:2] + rng.uniform(-0.6 * spread, 0.6 * spread, 2)
            rod = RodSpec((xy[0], xy[1], r), rng.uniform(-np.pi, np.pi), L, r)
            ends = np.array([rod.center + s * rod.axis * L / 2 for s in (-1, 1)])
            if off_robot(ends) and inside(np.concatenate([ends + [0, 0, r], ends - [0, 0, r]])):
                rods.append(rod)
                placed.append((xy, L / 2))
                break
        else:
            return None
    if want_neighbour:
        size = (rng.uniform(0.03, 0.05), rng.uniform(0.03, 0.06), rng.uniform(0.04, 0.06))
        g = float(rng.uniform(0.010, 0.040))
        if rods:
            rod = rods[0]
            side = np.array([-np.sin(rod.yaw), np.cos(rod.yaw)]) * rng.choice([-1.0, 1.0])
            along = rod.axis[:2] * rng.uniform(-0.35, 0.35) * L
            xy = np.asarray(rod.center[:2]) + along + side * (r + g + size[1] / 2)
            yaw = rod.yaw + rng.uniform(-0.15, 0.15)
        else:
            xy = target[:2] + rng.uniform(-spread, spread, 2) * 0.6
            yaw = rng.uniform(-np.pi, np.pi)
        box = BoxSpec((xy[0], xy[1], size[2] / 2), size, yaw, "black")
        if off_robot(box.corners()) and inside(box.corners()):
            boxes.append(box)
            placed.append((xy, 0.0))  # its gap to the rod is set on purpose
            gap = g if rods else None
    obstacle_idx: list[int] = []
    for _ in range(n_obstacles):
        size = (rng.uniform(0.08, 0.20), rng.uniform(0.06, 0.16), rng.uniform(0.04, 0.14))
        colour = str(rng.choice(HARD_OBSTACLE_COLORS))
        for _try in range(40):
            xy = target[:2] + rng.uniform(-spread, spread, 2)
            rad = 0.5 * float(np.hypot(size[0], size[1]))
            if not free(xy, rad):
                continue
            box = BoxSpec((xy[0], xy[1], size[2] / 2), size, rng.uniform(-np.pi, np.pi), colour)
            if off_robot(box.corners()) and inside(box.corners()):
                obstacle_idx.append(len(boxes))
                boxes.append(box)
                placed.append((xy, rad))
                break
    cut_idx: list[int] = []
    s = 0.05
    for k in range(n_cubes):
        colour = str(rng.choice(HARD_CUBE_COLORS))
        cut = want_partial and k == 0
        for _try in range(80):
            reach = 2.5 * spread if cut else spread
            xy = target[:2] + rng.uniform(-reach, reach, 2)
            if not free(xy, 0.75 * s):
                continue
            box = BoxSpec((xy[0], xy[1], s / 2), (s, s, s), rng.uniform(-np.pi, np.pi), colour)
            if off_robot(box.corners()) and (straddles(box.corners()) if cut else inside(box.corners())):
                if cut:
                    cut_idx.append(len(boxes))
                boxes.append(box)
                placed.append((xy, 0.75 * s))
                break
    return tuple(rods), tuple(boxes), tuple(obstacle_idx), gap, tuple(cut_idx)
