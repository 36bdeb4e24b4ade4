"""Seeded scenes of the cell: where the rod, the cubes and the obstacle are (pure, no MuJoCo).

Frames: the robot base frame, table top at z = 0. The rod's object frame has its z axis along the
cylinder axis (MuJoCo's cylinder convention); a cube's frame is at its centre with faces along
its axes. Same seed and settings → the same scene, and every seed gives one: when a layout drawn
from the seed cannot place every object (≈0.3 % of seeds with the sim profile), the layout is drawn
again from seeds derived from it (``SeedSequence([seed, k])``) and the scene records how many redraws
it took.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError
from services.common.settings import TwinSceneSettings

Array = np.ndarray

log = logging.getLogger("pickplace.sim.scene")

MAX_PLACEMENT_ATTEMPTS = 2000  # per object and layout draw
MAX_LAYOUT_REDRAWS = 64  # a layout fails for ≈0.3 % of draws: 64 independent redraws never all fail

COLORS_RGBA: dict[str, tuple[float, float, float, float]] = {
    "red": (0.80, 0.08, 0.08, 1.0),
    "blue": (0.08, 0.20, 0.80, 1.0),
    "green": (0.10, 0.62, 0.20, 1.0),
    "black": (0.05, 0.05, 0.05, 1.0),
    "yellow": (0.85, 0.74, 0.15, 1.0),
}


@dataclass(frozen=True)
class SceneObject:
    """A free object on the table at spawn time."""

    name: str  # "rod", "cube_red", ...
    kind: str  # "rod" | "cube"
    color: str
    size_m: tuple[float, float, float]  # rod: (diameter, diameter, length); cube: edges
    mass_kg: float
    position_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    inner_radius_m: float = 0.0  # rod only: hollow tube
    friction: float | None = None  # sliding friction against everything but the pads; None = the class's

    @property
    def T_base_object(self) -> Array:
        T = np.eye(4)
        w, x, y, z = self.quat_wxyz
        T[:3, :3] = Rotation.from_quat([x, y, z, w]).as_matrix()
        T[:3, 3] = self.position_m
        return T


@dataclass(frozen=True)
class BoxObstacle:
    name: str
    center_m: tuple[float, float, float]
    half_size_m: tuple[float, float, float]


@dataclass(frozen=True)
class Scene:
    seed: int
    objects: tuple[SceneObject, ...]
    obstacle: BoxObstacle | None
    layout_redraws: int = 0  # layouts drawn again from derived seeds before every object fitted
    table_z_m: float = 0.0  # height of the table top in the base frame (the objects stand on it)

    def get(self, name: str) -> SceneObject:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise InvalidInputError(f"scene has no object {name!r}; it has {[o.name for o in self.objects]}")


class _Unplaceable(Exception):
    """One layout draw could not place an object (the next draw comes from a derived seed)."""


@dataclass(frozen=True)
class _Footprint:
    """A 2-D capsule (segment + radius) covering an object's footprint on the table."""

    p0: Array
    p1: Array
    radius: float


def _segment_distance(a0: Array, a1: Array, b0: Array, b1: Array) -> float:
    def point_seg(p: Array, s0: Array, s1: Array) -> float:
        d = s1 - s0
        n = float(d @ d)
        t = 0.0 if n < 1e-18 else float(np.clip((p - s0) @ d / n, 0.0, 1.0))
        return float(np.linalg.norm(p - (s0 + t * d)))

    def cross(u: Array, v: Array) -> float:
        return float(u[0] * v[1] - u[1] * v[0])

    da, db, r = a1 - a0, b1 - b0, b0 - a0
    den = cross(da, db)
    if abs(den) > 1e-15:
        t, u = cross(r, db) / den, cross(r, da) / den
        if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0:
            return 0.0
    return min(point_seg(a0, b0, b1), point_seg(a1, b0, b1), point_seg(b0, a0, a1), point_seg(b1, a0, a1))


def _clear(fp: _Footprint, others: list[_Footprint], gap: float) -> bool:
    return all(_segment_distance(fp.p0, fp.p1, o.p0, o.p1) >= fp.radius + o.radius + gap for o in others)


def _inside(fp: _Footprint, lo: Array, hi: Array) -> bool:
    pts = np.stack([fp.p0, fp.p1])
    return bool(np.all(pts - fp.radius >= lo) and np.all(pts + fp.radius <= hi))


def _yaw_quat(yaw: float, lying: bool) -> tuple[float, float, float, float]:
    rot = Rotation.from_euler("z", yaw)
    if lying:  # cylinder axis (local z) → horizontal, along the yaw direction
        rot = rot * Rotation.from_euler("y", np.pi / 2)
    x, y, z, w = rot.as_quat()
    return (float(w), float(x), float(y), float(z))


def obstacle_of(settings: TwinSceneSettings) -> BoxObstacle | None:
    if not settings.obstacle:
        return None
    return BoxObstacle("obstacle", settings.obstacle_center_m, settings.obstacle_half_size_m)


def sample_scene(
    settings: TwinSceneSettings, seed: int, table_z_m: float = 0.0, rod_friction: float | None = None
) -> Scene:
    """Random rod pose (position in the pick zone, yaw) and cube layout, reproducible from ``seed``;
    redrawn from derived seeds when a draw cannot place every object (recorded on the scene).

    ``table_z_m`` raises the table top (and everything on it) above the base plane; ``rod_friction`` is the
    rod's own sliding friction (on the table and the cubes; the pads keep theirs)."""
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise InvalidInputError(f"scene seed must be a non-negative integer, got {seed!r}")
    last: _Unplaceable | None = None
    for k in range(MAX_LAYOUT_REDRAWS + 1):
        rng = np.random.default_rng(int(seed) if k == 0 else np.random.SeedSequence([int(seed), k]))
        try:
            objects, obstacle = _draw_layout(settings, rng, float(table_z_m), rod_friction)
        except _Unplaceable as exc:
            last = exc
            continue
        if k:
            log.info("scene seed %d: layout redrawn %d time(s) (%s)", seed, k, last)
        return Scene(
            seed=int(seed), objects=objects, obstacle=obstacle, layout_redraws=k, table_z_m=float(table_z_m)
        )
    raise InvalidInputError(
        f"{last} — in {MAX_LAYOUT_REDRAWS + 1} layouts from seed {seed}: enlarge the zone or remove objects"
    )


def _draw_layout(
    settings: TwinSceneSettings, rng: np.random.Generator, table_z: float, rod_friction: float | None
) -> tuple[tuple[SceneObject, ...], BoxObstacle | None]:
    lo = np.asarray(settings.pick_zone_min_m, dtype=float)
    hi = np.asarray(settings.pick_zone_max_m, dtype=float)
    placed: list[_Footprint] = []
    obstacle = obstacle_of(settings)
    if obstacle is not None and table_z:
        cx, cy, cz = obstacle.center_m
        obstacle = BoxObstacle(obstacle.name, (cx, cy, cz + table_z), obstacle.half_size_m)
    if obstacle is not None:
        c, h = np.asarray(obstacle.center_m[:2]), np.asarray(obstacle.half_size_m[:2])
        axis = 0 if h[0] >= h[1] else 1
        d = np.zeros(2)
        d[axis] = h[axis]
        placed.append(_Footprint(c - d, c + d, float(h[1 - axis])))

    objects: list[SceneObject] = []
    gap = settings.min_gap_m
    if settings.rod:
        r, half = settings.rod_diameter_m / 2, settings.rod_length_m / 2

        def rod_fp(xy: Array, yaw: float) -> _Footprint:
            d = half * np.array([np.cos(yaw), np.sin(yaw)])
            return _Footprint(xy - d, xy + d, r)

        xy, yaw = _place(rng, lo, hi, placed, gap, rod_fp, "rod")
        placed.append(rod_fp(xy, yaw))
        objects.append(
            SceneObject(
                name="rod",
                kind="rod",
                color="black",
                size_m=(2 * r, 2 * r, settings.rod_length_m),
                mass_kg=settings.rod_mass_kg,
                position_m=(float(xy[0]), float(xy[1]), table_z + r),
                quat_wxyz=_yaw_quat(yaw, lying=True),
                inner_radius_m=r - settings.rod_wall_m,
                friction=rod_friction,
            )
        )
    s = settings.cube_size_m
    for color in settings.cubes:

        def cube_fp(xy: Array, yaw: float) -> _Footprint:
            return _Footprint(xy, xy, s / np.sqrt(2))

        xy, yaw = _place(rng, lo, hi, placed, gap, cube_fp, f"cube_{color}")
        placed.append(cube_fp(xy, yaw))
        objects.append(
            SceneObject(
                name=f"cube_{color}",
                kind="cube",
                color=color,
                size_m=(s, s, s),
                mass_kg=settings.cube_mass_kg,
                position_m=(float(xy[0]), float(xy[1]), table_z + s / 2),
                quat_wxyz=_yaw_quat(yaw, lying=False),
            )
        )
    return tuple(objects), obstacle


def _place(
    rng: np.random.Generator,
    lo: Array,
    hi: Array,
    placed: list[_Footprint],
    gap: float,
    footprint: Callable[[Array, float], _Footprint],
    name: str,
) -> tuple[Array, float]:
    for _ in range(MAX_PLACEMENT_ATTEMPTS):
        xy = rng.uniform(lo, hi)
        yaw = float(rng.uniform(-np.pi / 2, np.pi / 2))
        fp = footprint(xy, yaw)
        if _inside(fp, lo, hi) and _clear(fp, placed, gap):
            return xy, yaw
    raise _Unplaceable(
        f"cannot place {name} in the pick zone {lo.tolist()}..{hi.tolist()} m with a {gap} m gap "
        f"after {MAX_PLACEMENT_ATTEMPTS} tries"
    )


def hollow_tube_inertia(mass_kg: float, outer_r: float, inner_r: float, length: float) -> tuple[float, float]:
    """(I_perpendicular, I_axial) of a thin-walled tube about its centre, kg·m²."""
    r2 = outer_r**2 + inner_r**2
    return mass_kg * (3 * r2 + length**2) / 12.0, mass_kg * r2 / 2.0
