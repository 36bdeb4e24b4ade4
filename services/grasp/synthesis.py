"""Antipodal grasp synthesis for boxes, cylinders and spheres (LLD §4.2), scored and filtered.

Pipeline of :func:`compute_grasps`:

1. **Candidates** in the object frame (:mod:`services.grasp.candidates`): pads on opposite faces
   (box), across the diameter or on the flat ends (cylinder), through the centre (sphere); several
   approach directions, jaw orientations (the two 180°-symmetric wrist options) and offsets along
   the free axis. Sampling around a cylinder's axis is anchored to gravity, so a lying cylinder
   always gets the exact top-down grasp.
2. **Geometric filters** in the base frame: the object fits the stroke, no approach from below,
   the fingers and palm stay above the table at the grasp and the pre-grasp.
3. **Force closure**: each pad's contact is a line of point contacts (flat pad on a face or along a
   cylinder) or a single soft-finger point (sphere); :mod:`force_closure` gives ε; grasps without
   force closure are dropped.
4. **Quality** in [0, 1]: 0.3 · the LLD width score (1 − |w/w_max − 0.5|·0.5) + 0.4 · ε relative to
   the best ε of the request + 0.2 · top-down-ness of the approach + 0.1 · centring.
5. **Reachability** (batched closed-form IK, one branch along the straight approach line) and an
   optional **collision** check of the pre-grasp and grasp configurations; the survivors are
   ranked by quality, then by joint motion from the seed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from services.common.errors import InvalidInputError
from services.common.frames import check_transform, invert_transform
from services.common.settings import GraspGripperSettings, GraspSettings
from services.grasp.candidates import Candidate, box_candidates, cylinder_candidates, sphere_candidates
from services.grasp.force_closure import ContactModel, evaluate_force_closure
from services.grasp.geometry import lowest_gripper_z, pose_path
from services.grasp.plan import Grasp, HeldObject
from services.grasp.reach import TrackLimits, track_paths
from services.kinematics.robot_models import RobotSpec

Array = np.ndarray

SHAPES = ("box", "cylinder", "sphere")
W_WIDTH, W_EPS, W_APPROACH, W_CENTER = 0.3, 0.4, 0.2, 0.1
MAX_APPROACH_UP = 0.05  # tool z may point at most this much upward (z component): no grasps from below

CollisionCheck = Callable[[Array, HeldObject | None], bool]


@dataclass(frozen=True)
class ObjectSpec:
    """An object to grasp: shape, pose and size (LLD ComputeGrasps request).

    ``dims``: box = sizes along object x, y, z; cylinder = (diameter, diameter, length along z);
    sphere = (diameter, diameter, diameter).
    """

    shape: str
    T_base_object: Array
    dims: tuple[float, float, float]

    @classmethod
    def from_request(
        cls, shape: str, T_base_object: ArrayLike, width: float, depth: float, height: float
    ) -> ObjectSpec:
        if shape not in SHAPES:
            raise InvalidInputError(f"object shape must be one of {list(SHAPES)}, got {shape!r}")
        T = check_transform(T_base_object, "object pose")
        vals = {"width": width, "depth": depth, "height": height}
        needed = {"box": ("width", "depth", "height"), "cylinder": ("width", "height"), "sphere": ("width",)}[
            shape
        ]
        for name in needed:
            v = vals[name]
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 2.0):
                raise InvalidInputError(f"{shape} {name} must be within (0, 2] m, got {v!r}")
        if shape == "box":
            dims = (float(width), float(depth), float(height))
        elif shape == "cylinder":
            dims = (float(width), float(width), float(height))
        else:
            dims = (float(width),) * 3
        return cls(shape, T, dims)

    @property
    def characteristic_length(self) -> float:
        """Torque scale of the wrench space: the largest half-extent."""
        return max(self.dims) / 2

    def held(self, T_tool_object: Array) -> HeldObject:
        if self.shape == "box":
            return HeldObject("box", T_tool_object, size=self.dims)
        if self.shape == "cylinder":
            return HeldObject("cylinder", T_tool_object, radius=self.dims[0] / 2, length=self.dims[2])
        # a sphere is carried as its bounding box (motion checks cylinders and boxes)
        return HeldObject("box", T_tool_object, size=self.dims)


@dataclass
class GraspSet:
    grasps: list[Grasp]
    generated: int = 0
    rejected: dict[str, int] = field(default_factory=dict)

    def summary(self) -> str:
        rej = ", ".join(f"{v} {k}" for k, v in self.rejected.items() if v) or "none"
        return f"{len(self.grasps)} grasps from {self.generated} candidates (rejected: {rej})"


# --- candidates (object frame) --------------------------------------------------------------------
def candidates_for(obj: ObjectSpec, cfg: GraspSettings, stroke_m: float) -> list[Candidate]:
    down_obj = obj.T_base_object[:3, :3].T @ np.array([0.0, 0.0, -1.0])
    if obj.shape == "box":
        return box_candidates(obj.dims, cfg, stroke_m)
    if obj.shape == "cylinder":
        return cylinder_candidates(obj.dims[0] / 2, obj.dims[2], cfg, stroke_m, down_obj)
    return sphere_candidates(obj.dims[0] / 2, cfg, stroke_m, down_obj)


# --- scoring --------------------------------------------------------------------------------------
def width_quality(width_m: float, stroke_m: float) -> float:
    """LLD §4.2: 1 − |w/w_max − 0.5|·0.5, and 0 when the object does not fit."""
    if width_m > stroke_m:
        return 0.0
    return float(np.clip(1.0 - abs(width_m / stroke_m - 0.5) * 0.5, 0.0, 1.0))


def contact_model(cfg: GraspSettings) -> ContactModel:
    fc = cfg.force_closure
    return ContactModel(fc.friction_coefficient, fc.cone_edges, fc.torsional_friction_m)


def synthesize(obj: ObjectSpec, cfg: GraspSettings, stroke_m: float) -> GraspSet:
    """Candidates → geometric filters → force closure → quality (no reachability yet)."""
    g = cfg.gripper
    cands = candidates_for(obj, cfg, stroke_m)
    result = GraspSet([], generated=len(cands), rejected={"from below": 0, "table": 0, "no force closure": 0})
    if not cands:
        return result
    T_obj = obj.T_base_object
    T_tools = np.einsum("ij,njk->nik", T_obj, np.stack([c.T_object_tool for c in cands]))
    approach = T_tools[:, :3, 2]
    openings = np.array([min(stroke_m, c.width + g.width_margin_m) for c in cands])
    floor = cfg.table_z_m + g.table_clearance_m
    model = contact_model(cfg)
    cache: dict[bytes, tuple[bool, float]] = {}
    kept: list[tuple[Candidate, Array, float, bool]] = []
    for n, c in enumerate(cands):
        if approach[n, 2] > MAX_APPROACH_UP:
            result.rejected["from below"] += 1
            continue
        T_n = _clear_table(c, T_tools[n], openings[n], floor, g)
        if T_n is None:
            result.rejected["table"] += 1
            continue
        T_pre_n = T_n.copy()
        T_pre_n[:3, 3] -= cfg.approach_distance_m * approach[n]
        if lowest_gripper_z(g, T_pre_n, openings[n]) < floor:
            result.rejected["table"] += 1
            continue
        T_tools[n] = T_n
        key = np.round(np.hstack([c.points, c.normals]), 6).tobytes()
        if key not in cache:
            fc = evaluate_force_closure(c.points, c.normals, model, obj.characteristic_length)
            cache[key] = (fc.force_closure, fc.epsilon)
        closure, eps = cache[key]
        if not closure:
            result.rejected["no force closure"] += 1
            continue
        kept.append((c, T_tools[n], eps, closure))
    if not kept:
        return result
    eps_best = max(k[2] for k in kept)
    for c, T, eps, closure in kept:
        wq = width_quality(c.width, stroke_m)
        top = (1.0 - T[2, 2]) / 2  # 1 when approaching straight down
        q = W_WIDTH * wq + W_EPS * (eps / eps_best) + W_APPROACH * top + W_CENTER * c.centering
        result.grasps.append(
            Grasp(
                T_base_tool=T,
                width_m=c.width,
                opening_m=min(stroke_m, c.width + g.width_margin_m),
                quality=round(float(np.clip(q, 0.0, 1.0)), 6),
                width_quality=wq,
                epsilon=eps,
                force_closure=closure,
                approach_direction=T[:3, 2].copy(),
                approach_distance_m=cfg.approach_distance_m,
                force_n=g.grip_force_n,
                contacts_base=(T_obj[:3, :3] @ c.points.T).T + T_obj[:3, 3],
                label=c.label,
            )
        )
    result.grasps.sort(key=lambda gr: -gr.quality)
    return result


def _clear_table(
    c: Candidate, T_base_tool: Array, opening_m: float, floor_z: float, g: GraspGripperSettings
) -> Array | None:
    """The grasp pose, backed off along the approach until the gripper clears the table while the
    pads still cover the contacts (a lying rod is grasped a millimetre above its axis); None if not."""
    deficit = floor_z - float(lowest_gripper_z(g, T_base_tool, opening_m))
    if deficit <= 0:
        return T_base_tool
    a_z = T_base_tool[2, 2]
    if a_z > -0.1:
        return None
    shift = deficit / -a_z + 1e-6
    T_tool_object = invert_transform(c.T_object_tool)
    contact_z = c.points @ T_tool_object[2, :3] + T_tool_object[2, 3]  # along the approach, from the TCP
    if np.any(np.abs(contact_z + shift) > g.pad_height_m / 2):
        return None
    T = T_base_tool.copy()
    T[:3, 3] -= shift * T[:3, 2]
    return T


# --- reachability and collision -------------------------------------------------------------------
def approach_path(T_grasp: Array, distance_m: float, step_m: float) -> Array:
    """Tool poses (N, 4, 4) from the pre-grasp down the approach axis to the grasp."""
    T_pre = T_grasp.copy()
    T_pre[:3, 3] -= distance_m * T_grasp[:3, 2]
    return pose_path(T_pre, T_grasp, step_m, max(1, math.ceil(distance_m / step_m - 1e-9)))


def track_limits(cfg: GraspSettings) -> TrackLimits:
    return TrackLimits(
        jump_threshold_rad=math.radians(cfg.jump_threshold_deg),
        min_singularity_sin=math.sin(math.radians(cfg.min_singularity_deg)),
        arm_table_clearance_m=cfg.arm_table_clearance_m,
        table_z_m=cfg.table_z_m,
    )


def filter_reachable(
    grasps: list[Grasp],
    spec: RobotSpec,
    T_flange_tool: Array,
    seed: Array,
    cfg: GraspSettings,
    collision_check: CollisionCheck | None = None,
    rejected: dict[str, int] | None = None,
) -> list[Grasp]:
    """Grasps whose approach line the arm follows in one IK branch (and collision-free), with joints."""
    if not grasps:
        return []
    T_tool_flange = invert_transform(T_flange_tool)
    paths = np.stack(
        [approach_path(gr.T_base_tool, cfg.approach_distance_m, cfg.path_step_m) for gr in grasps]
    )
    res = track_paths(spec, paths @ T_tool_flange, seed, track_limits(cfg))
    out: list[tuple[float, Grasp]] = []
    rej = rejected if rejected is not None else {}
    rej.setdefault("unreachable", 0)
    rej.setdefault("collision", 0)
    for b, gr in enumerate(grasps):
        if not res.ok[b]:
            rej["unreachable"] += 1
            continue
        q_pre, q_grasp = res.q[b, 0], res.q[b, -1]
        if collision_check is not None and (collision_check(q_pre, None) or collision_check(q_grasp, None)):
            rej["collision"] += 1
            continue
        out.append((float(res.cost[b]), replace(gr, q=q_grasp.copy())))
    out.sort(key=lambda t: (-t[1].quality, t[0]))
    return [g for _, g in out]


def compute_grasps(
    obj: ObjectSpec,
    spec: RobotSpec,
    T_flange_tool: Array,
    seed: Array,
    cfg: GraspSettings,
    stroke_m: float,
    collision_check: CollisionCheck | None = None,
    num_candidates: int | None = None,
    check_reach: bool = True,
) -> GraspSet:
    """Ranked, force-closed, reachable grasps for ``obj`` (best first, at most ``num_candidates``)."""
    result = synthesize(obj, cfg, stroke_m)
    if check_reach:
        result.grasps = filter_reachable(
            result.grasps, spec, T_flange_tool, seed, cfg, collision_check, result.rejected
        )
    result.grasps = result.grasps[: num_candidates or cfg.num_candidates]
    return result
