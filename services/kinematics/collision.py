"""Collision checking with coal through pinocchio's GeometryModel.

What is checked (:class:`CollisionChecker`):
- self-collision between the arm's link capsules and the gripper, adjacent links excluded;
- the table: the half-space below ``table_z`` (links from the upper arm on; the base and
  the J1 column stand on it);
- axis-aligned boxes in the base frame (the vision service's obstacle boxes), each
  optionally extended along ±y as in seed 004 so the planner goes over, not around;
- an attached object (the grasped rod: a cylinder, or a box) carried with the tool,
  against the environment and the arm (except the gripper holding it and the flange).

``padding_m`` is a safety margin applied to every arm/object–environment pair (coal's
security margin). Pairs can be allowed by group name (``allowed``): link names
(``Link2``, ``wrist_1_link``…), ``gripper``, ``table``, a box's name, ``attached``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from services.common.errors import InvalidInputError
from services.kinematics.model import ArmModel
from services.kinematics.trajectory import Array, JointTrajectory, joint_path

TABLE = "table"
ATTACHED = "attached"
GRIPPER = "gripper"


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in the base frame (m)."""

    min: tuple[float, float, float]
    max: tuple[float, float, float]
    name: str = "box"

    def __post_init__(self) -> None:
        lo = np.asarray(self.min, dtype=float)
        hi = np.asarray(self.max, dtype=float)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise InvalidInputError(
                f"box {self.name!r} needs finite 3-vectors, got min={self.min} max={self.max}"
            )
        if np.any(hi <= lo):
            raise InvalidInputError(
                f"box {self.name!r} max {self.max} must exceed min {self.min} on every axis"
            )
        if not self.name or self.name in (TABLE, ATTACHED, GRIPPER):
            raise InvalidInputError(f"box name {self.name!r} is empty or reserved")
        object.__setattr__(self, "min", tuple(float(v) for v in lo))
        object.__setattr__(self, "max", tuple(float(v) for v in hi))

    @classmethod
    def from_bounds(
        cls,
        x_min: float,
        x_max: float,
        y_min: float,
        y_max: float,
        z_min: float,
        z_max: float,
        name: str = "box",
    ) -> Box:
        """Seed 004's BoxBounds message layout."""
        return cls((x_min, y_min, z_min), (x_max, y_max, z_max), name)

    def extended_y(self, extension_m: float) -> Box:
        """Seed 004: stretched by ``extension_m`` in ±y so plans go over the obstacle, not around it."""
        if not (math.isfinite(extension_m) and extension_m >= 0):
            raise InvalidInputError(f"y-extension must be a non-negative length, got {extension_m}")
        return Box(
            (self.min[0], self.min[1] - extension_m, self.min[2]),
            (self.max[0], self.max[1] + extension_m, self.max[2]),
            self.name,
        )

    @property
    def center(self) -> Array:
        return (np.asarray(self.min) + np.asarray(self.max)) / 2

    @property
    def size(self) -> Array:
        return np.asarray(self.max) - np.asarray(self.min)


@dataclass(frozen=True)
class AttachedObject:
    """An object held by the gripper, posed in the tool frame by ``T_tool_object``.

    ``shape``: ``cylinder`` (axis = object z; ``radius``, ``length``) or ``box`` (``size``).
    """

    shape: str = "cylinder"
    radius: float = 0.011
    length: float = 0.2
    size: tuple[float, float, float] = (0.05, 0.05, 0.05)
    T_tool_object: tuple[tuple[float, ...], ...] = (
        (1.0, 0, 0, 0),
        (0, 1.0, 0, 0),
        (0, 0, 1.0, 0),
        (0, 0, 0, 1.0),
    )

    def __post_init__(self) -> None:
        if self.shape not in ("cylinder", "box"):
            raise InvalidInputError(f"attached object shape must be 'cylinder' or 'box', got {self.shape!r}")
        dims = [self.radius, self.length] if self.shape == "cylinder" else list(self.size)
        if not all(math.isfinite(v) and v > 0 for v in dims):
            raise InvalidInputError(f"attached {self.shape} dimensions must be positive, got {dims}")
        from services.common.frames import check_transform

        T = check_transform(np.asarray(self.T_tool_object, dtype=float), "attached object pose T_tool_object")
        object.__setattr__(self, "T_tool_object", tuple(tuple(float(v) for v in row) for row in T))

    def geometry(self) -> coal.CollisionGeometry:
        if self.shape == "cylinder":
            return coal.Cylinder(self.radius, self.length)
        return coal.Box(*self.size)


@dataclass(frozen=True)
class Scene:
    """The environment of one planning request."""

    boxes: tuple[Box, ...] = ()
    table_z: float | None = 0.0
    attached: AttachedObject | None = None
    # A clearance kept from the table and boxes. Checking states 1° apart, a link can graze an
    # obstacle between two checked states by up to r - sqrt(r² - (d/2)²) (d: how far it moves per
    # step, r: its radius) — a few mm for the rod at the tool tip; 1 cm covers that.
    padding_m: float = 0.01
    box_y_extension_m: float = 0.0
    allowed: frozenset[tuple[str, str]] = field(default_factory=frozenset)

    def __post_init__(self) -> None:
        if self.table_z is not None and not math.isfinite(self.table_z):
            raise InvalidInputError(f"table height must be finite, got {self.table_z}")
        if not (math.isfinite(self.padding_m) and 0 <= self.padding_m <= 0.2):
            raise InvalidInputError(f"padding must be within [0, 0.2] m, got {self.padding_m}")
        if not (math.isfinite(self.box_y_extension_m) and self.box_y_extension_m >= 0):
            raise InvalidInputError(f"box y-extension must be >= 0 m, got {self.box_y_extension_m}")
        names = [b.name for b in self.boxes]
        if len(set(names)) != len(names):
            raise InvalidInputError(f"box names must be unique, got {names}")
        object.__setattr__(self, "boxes", tuple(self.boxes))
        object.__setattr__(self, "allowed", frozenset(tuple(sorted(p)) for p in self.allowed))


def _group(name: str) -> str:
    """Geometry object name (``Link2_0``) → its group (``Link2``)."""
    head, _, tail = name.rpartition("_")
    return head if tail.isdigit() and head else name


class CollisionChecker:
    """State and path collision checks for one arm + scene. Holds pinocchio data: one per thread."""

    def __init__(self, arm: ArmModel, scene: Scene | None = None):
        self.arm = arm
        self.scene = scene or Scene()
        self.model = arm.model
        self.data = arm.model.createData()
        self.geom = arm.collision_model.copy()
        robot_ids = list(range(self.geom.ngeoms))
        env_ids: list[int] = []
        if self.scene.table_z is not None:
            # coal's half-space n·x <= d is the solid side: everything below the table top
            table = pin.GeometryObject(
                TABLE,
                0,
                pin.SE3.Identity(),
                coal.Halfspace(np.array([0.0, 0.0, 1.0]), float(self.scene.table_z)),
            )
            env_ids.append(self.geom.addGeometryObject(table))
        for box in self.scene.boxes:
            b = box.extended_y(self.scene.box_y_extension_m) if self.scene.box_y_extension_m else box
            obj = pin.GeometryObject(b.name, 0, pin.SE3(np.eye(3), b.center), coal.Box(*b.size))
            env_ids.append(self.geom.addGeometryObject(obj))
        attached_id = None
        if self.scene.attached is not None:
            tool = arm.model.frames[arm.tool_frame]
            placement = tool.placement * pin.SE3(np.asarray(self.scene.attached.T_tool_object))
            obj = pin.GeometryObject(ATTACHED, tool.parentJoint, placement, self.scene.attached.geometry())
            attached_id = self.geom.addGeometryObject(obj)
        self._add_pairs(robot_ids, env_ids, attached_id)
        self.geom_data = pin.GeometryData(self.geom)
        env_names = {TABLE, *(bx.name for bx in self.scene.boxes)}
        for k in range(len(self.geom.collisionPairs)):
            if env_names.intersection(self._names(k)):
                self.geom_data.collisionRequests[k].security_margin = self.scene.padding_m

    def _names(self, pair_index: int) -> tuple[str, str]:
        cp = self.geom.collisionPairs[pair_index]
        return self.geom.geometryObjects[cp.first].name, self.geom.geometryObjects[cp.second].name

    def _add_pairs(self, robot_ids: list[int], env_ids: list[int], attached_id: int | None) -> None:
        objs = self.geom.geometryObjects
        allowed = self.scene.allowed
        n_joints = self.model.njoints - 1

        def permitted(a: int, b: int) -> bool:
            ga, gb = _group(objs[a].name), _group(objs[b].name)
            return tuple(sorted((ga, gb))) not in allowed

        pairs: list[tuple[int, int]] = []
        for i, a in enumerate(robot_ids):
            for b in robot_ids[i + 1 :]:
                # links on the same or neighbouring joints always touch at the joint: skip them
                if abs(objs[a].parentJoint - objs[b].parentJoint) >= 2:
                    pairs.append((a, b))
        for e in env_ids:
            is_table = objs[e].name == TABLE
            for a in robot_ids:
                # the base and the J1 column stand on the table
                if is_table and objs[a].parentJoint < 2:
                    continue
                pairs.append((a, e))
        if attached_id is not None:
            for a in robot_ids:
                if objs[a].parentJoint < n_joints:  # not the flange or the gripper holding it
                    pairs.append((a, attached_id))
            pairs.extend((attached_id, e) for e in env_ids)
        for a, b in pairs:
            if permitted(a, b):
                self.geom.addCollisionPair(pin.CollisionPair(min(a, b), max(a, b)))

    # --- queries ------------------------------------------------------------------------------
    @property
    def dof(self) -> int:
        return self.arm.spec.dof

    @property
    def pair_count(self) -> int:
        return len(self.geom.collisionPairs)

    def in_collision(self, q: Array) -> bool:
        """True when any checked pair collides at q (q assumed valid: callers validate inputs)."""
        return bool(pin.computeCollisions(self.model, self.data, self.geom, self.geom_data, q, True))

    def contacts(self, q: ArrayLike) -> list[tuple[str, str]]:
        """Every colliding pair at q, by group name (e.g. ``("Link3", "box")``)."""
        qv = joint_path(q, self.dof, "joint positions")[0]
        pin.computeCollisions(self.model, self.data, self.geom, self.geom_data, qv, False)
        out = []
        for k in range(len(self.geom.collisionPairs)):
            if self.geom_data.collisionResults[k].isCollision():
                a, b = self._names(k)
                pair = (_group(a), _group(b))
                if pair not in out:
                    out.append(pair)
        return out

    def explain(self, q: ArrayLike) -> str:
        pairs = self.contacts(q)
        return ", ".join(f"{a} with {b}" for a, b in pairs) if pairs else "no contact"

    def min_distance(self, q: ArrayLike) -> float:
        """Smallest distance (m) over the checked pairs at q (negative: penetration)."""
        qv = joint_path(q, self.dof, "joint positions")[0]
        pin.computeDistances(self.model, self.data, self.geom, self.geom_data, qv)
        return float(min((r.min_distance for r in self.geom_data.distanceResults), default=math.inf))

    def segment_free(self, q_a: Array, q_b: Array, resolution_rad: float) -> bool:
        """True when the straight joint segment a → b is collision-free at the resolution.

        Intermediate states are tested in bisection order (midpoint first), so a blocked
        segment is usually found after a few checks; both ends are tested too.
        """
        n = max(1, math.ceil(float(np.max(np.abs(q_b - q_a))) / resolution_rad))
        states = q_a + np.linspace(0.0, 1.0, n + 1)[:, None] * (q_b - q_a)
        model, data, geom, gdata = self.model, self.data, self.geom, self.geom_data
        for k in _bisection_order(n):
            if pin.computeCollisions(model, data, geom, gdata, states[k], True):
                return False
        return True

    def first_collision_on_segment(self, q_a: Array, q_b: Array, resolution_rad: float) -> Array | None:
        """The first colliding configuration on the straight joint segment a → b, or None.

        Checked at joint steps of at most ``resolution_rad`` (both ends included).
        """
        n = max(1, math.ceil(float(np.max(np.abs(q_b - q_a))) / resolution_rad))
        for s in np.linspace(0.0, 1.0, n + 1):
            q = q_a + s * (q_b - q_a)
            if self.in_collision(q):
                return q
        return None

    def first_collision_on_path(self, path: ArrayLike, resolution_rad: float) -> tuple[int, Array] | None:
        """(segment index, configuration) of the first collision along a polyline, or None."""
        p = joint_path(path, self.dof, "path")
        if not (math.isfinite(resolution_rad) and resolution_rad > 0):
            raise InvalidInputError(f"collision resolution must be positive, got {resolution_rad}")
        if p.shape[0] == 1:
            return (0, p[0]) if self.in_collision(p[0]) else None
        for k in range(p.shape[0] - 1):
            hit = self.first_collision_on_segment(p[k], p[k + 1], resolution_rad)
            if hit is not None:
                return k, hit
        return None

    def first_collision_in_trajectory(
        self, traj: JointTrajectory, resolution_rad: float
    ) -> tuple[float, Array] | None:
        """(time, configuration) of the first collision of a timed trajectory, or None.

        Samples so that no joint moves more than ``resolution_rad`` between samples.
        """
        if not (math.isfinite(resolution_rad) and resolution_rad > 0):
            raise InvalidInputError(f"collision resolution must be positive, got {resolution_rad}")
        vmax = float(np.max(np.abs(traj.velocities))) if len(traj) else 0.0
        # knot velocities bound the motion between knots up to the interpolation's small overshoot
        n = max(len(traj), math.ceil(traj.duration * max(vmax, 1e-9) * 1.5 / resolution_rad) + 1)
        ts = np.union1d(np.linspace(0.0, traj.duration, n), traj.times)
        (qs,) = traj.sample(ts, derivatives=0)
        for t, q in zip(ts, qs, strict=True):
            if self.in_collision(q):
                return float(t), q
        return None


@functools.lru_cache(maxsize=256)
def _bisection_order(n: int) -> tuple[int, ...]:
    """Indices 0..n: the two ends, then midpoints of ever finer halvings (van der Corput order)."""
    order = [n, 0]
    seen = {0, n}
    step: float = n
    while step > 1:
        half = step / 2
        k = half
        while k < n:
            i = round(k)
            if i not in seen:
                seen.add(i)
                order.append(i)
            k += step
        step = half
    order.extend(i for i in range(n + 1) if i not in seen)
    return tuple(order)


def scene_from_boxes(boxes: Iterable[Sequence[float]], **kwargs: Any) -> Scene:
    """Scene from seed-004 style bounds (x_min, x_max, y_min, y_max, z_min, z_max) per box."""
    out = []
    for k, b in enumerate(boxes):
        vals = list(b)
        if len(vals) != 6:
            raise InvalidInputError(
                f"box {k} needs 6 bounds (x_min, x_max, y_min, y_max, z_min, z_max), got {vals}"
            )
        x_min, x_max, y_min, y_max, z_min, z_max = vals
        out.append(Box.from_bounds(x_min, x_max, y_min, y_max, z_min, z_max, name=f"box{k}"))
    return Scene(boxes=tuple(out), **kwargs)
