"""Ground truth of the twin — for evaluation code only.

Object poses, contacts, the true camera pose and the success checks of a trial. Perception,
grasp, motion and task code must never import this module: they see the cell through the camera,
the calibration file and the robot's feedback, as on hardware.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from services.common.errors import InvalidInputError
from services.common.frames import (
    invert_transform,
    make_transform,
    rotation_angle_rad,
    tilt_from_vertical_deg,
)
from services.common.settings import TwinCameraSettings
from services.sim.twin.engine import TwinEngine
from services.sim.twin.mjcf import camera_axes, camera_pose

Array = np.ndarray

REST_LINEAR_M_S = 0.005
REST_ANGULAR_RAD_S = 0.05
ON_TABLE_TOL_M = 0.003


@dataclass(frozen=True)
class Contact:
    geom_a: str
    geom_b: str
    body_a: str
    body_b: str
    normal_force_n: float


@dataclass(frozen=True)
class RodStandResult:
    success: bool
    tilt_deg: float
    lowest_point_m: float
    at_rest: bool
    gripper_open: bool
    gripper_clear: bool
    reasons: tuple[str, ...] = ()


@dataclass(frozen=True)
class CubePlaceResult:
    success: bool
    distance_m: float
    at_rest: bool
    reasons: tuple[str, ...] = ()


@dataclass
class GraspMetrics:
    """Intermediate metrics of a rod trial (the notes: report these, not only success)."""

    slip_mm: float = 0.0  # largest drift of the rod in the tool frame while held
    slip_deg: float = 0.0
    tilt_before_place_deg: float | None = None
    tilt_after_release_deg: float | None = None
    extra: dict[str, float] = field(default_factory=dict)


def T_base_camera(camera: TwinCameraSettings) -> Array:
    """Nominal pose of the optical frame (x right, y down, z forward) in the base frame: the true one of
    an unvaried world (:func:`true_T_base_camera` for a randomized one)."""
    right, up, fwd = camera_axes(camera)
    return make_transform(np.column_stack([right, -up, fwd]), camera.position_m)


def true_T_base_camera(engine: TwinEngine) -> Array:
    """Where this world's camera really is (its mount error included)."""
    w = engine.world
    return camera_pose(w.twin.camera, w.variation if w.variation.randomized else None)


def _check_name(engine: TwinEngine, name: str) -> int:
    try:
        return engine.world.object_body[name]
    except KeyError as exc:
        raise InvalidInputError(
            f"the twin has no object {name!r}; it has {sorted(engine.world.object_body)}"
        ) from exc


def object_pose(engine: TwinEngine, name: str) -> Array:
    """T_base_object of a free object (rod: z along the cylinder axis)."""
    b = _check_name(engine, name)
    with engine.lock:
        return make_transform(engine.data.xmat[b].reshape(3, 3).copy(), engine.data.xpos[b].copy())


def object_poses(engine: TwinEngine) -> dict[str, Array]:
    return {name: object_pose(engine, name) for name in engine.world.object_body}


def tool_pose(engine: TwinEngine) -> Array:
    """T_base_tool: the grasp centre between the pads, axes of the flange."""
    s = engine.world.tool_site
    with engine.lock:
        return make_transform(engine.data.site_xmat[s].reshape(3, 3).copy(), engine.data.site_xpos[s].copy())


def object_velocity(engine: TwinEngine, name: str) -> tuple[float, float]:
    """(linear m/s, angular rad/s) speed of a free object."""
    _check_name(engine, name)
    dof = engine.world.object_dof[name]
    with engine.lock:
        v = engine.data.qvel[dof : dof + 6].copy()
    return float(np.linalg.norm(v[:3])), float(np.linalg.norm(v[3:]))


def contacts(engine: TwinEngine) -> list[Contact]:
    m = engine.model
    out: list[Contact] = []
    f6 = np.zeros(6)
    with engine.lock:
        d = engine.data
        for i in range(d.ncon):
            mujoco.mj_contactForce(m, d, i, f6)
            ga, gb = (int(g) for g in d.contact.geom[i])  # geom1/geom2 are deprecated in MuJoCo 4
            out.append(
                Contact(
                    geom_a=engine.world.geom_name(ga),
                    geom_b=engine.world.geom_name(gb),
                    body_a=m.body(int(m.geom_bodyid[ga])).name,
                    body_b=m.body(int(m.geom_bodyid[gb])).name,
                    normal_force_n=float(f6[0]),
                )
            )
    return out


def robot_touches(engine: TwinEngine, name: str) -> bool:
    """True when any arm or gripper geom is in contact with the object."""
    b = _check_name(engine, name)
    w = engine.world
    with engine.lock:
        d = engine.data
        for i in range(d.ncon):
            g1, g2 = (int(g) for g in d.contact.geom[i])
            b1, b2 = int(engine.model.geom_bodyid[g1]), int(engine.model.geom_bodyid[g2])
            if (w.robot_geom[g1] and b2 == b) or (w.robot_geom[g2] and b1 == b):
                return True
    return False


def axis_tilt_deg(T_base_object: Array) -> float:
    """Angle between the object's z axis and the vertical, folded to 0..90° (up or down)."""
    return tilt_from_vertical_deg(np.asarray(T_base_object)[:3, 2])


def slip(T_tool_object_ref: Array, T_tool_object_now: Array) -> tuple[float, float]:
    """Drift of a held object in the tool frame: (mm, deg)."""
    delta = invert_transform(np.asarray(T_tool_object_ref)) @ np.asarray(T_tool_object_now)
    angle = np.degrees(rotation_angle_rad(np.eye(3), delta[:3, :3]))
    return float(np.linalg.norm(delta[:3, 3]) * 1000.0), float(angle)


def T_tool_object(engine: TwinEngine, name: str) -> Array:
    return invert_transform(tool_pose(engine)) @ object_pose(engine, name)


def check_rod_standing(engine: TwinEngine, name: str = "rod", max_tilt_deg: float = 5.0) -> RodStandResult:
    """The rod stands: axis within ``max_tilt_deg`` of vertical, base on the table, at rest, and the
    gripper open and not touching it. Call after the settling time (see :func:`evaluate_rod_standing`)."""
    obj = engine.scene.get(name)
    T = object_pose(engine, name)
    tilt = axis_tilt_deg(T)
    axis = T[:3, 2]
    radius, half = obj.size_m[0] / 2, obj.size_m[2] / 2
    rim = radius * np.sqrt(max(0.0, 1.0 - axis[2] ** 2))
    lowest = float(min(T[2, 3] + half * axis[2], T[2, 3] - half * axis[2]) - rim) - engine.scene.table_z_m
    lin, ang = object_velocity(engine, name)
    at_rest = lin < REST_LINEAR_M_S and ang < REST_ANGULAR_RAD_S
    opened = (not engine.gripper_closed) and engine.gripper_opening_m > obj.size_m[0] + 0.002
    clear = not robot_touches(engine, name)
    reasons = []
    if tilt > max_tilt_deg:
        reasons.append(f"tilted {tilt:.1f}° (> {max_tilt_deg}°)")
    if abs(lowest) > ON_TABLE_TOL_M:
        reasons.append(f"lowest point {lowest * 1000:.1f} mm from the table top, not on the table")
    if not at_rest:
        reasons.append(f"moving ({lin * 1000:.1f} mm/s, {np.degrees(ang):.1f}°/s)")
    if not opened:
        reasons.append("gripper not open")
    if not clear:
        reasons.append("gripper touches the rod")
    return RodStandResult(not reasons, tilt, lowest, at_rest, opened, clear, tuple(reasons))


def evaluate_rod_standing(
    engine: TwinEngine, name: str = "rod", settle_s: float = 1.0, max_tilt_deg: float = 5.0
) -> RodStandResult:
    """Let the cell settle for ``settle_s`` (arm holding still), then check the rod."""
    engine.settle(settle_s)
    return check_rod_standing(engine, name, max_tilt_deg)


def check_cube_in_zone(engine: TwinEngine, color: str, tolerance_m: float = 0.025) -> CubePlaceResult:
    """The cube of ``color`` rests within ``tolerance_m`` (horizontal) of its drop-zone centre."""
    zones = engine.world.twin.scene.drop_zones_m
    if color not in zones:
        raise InvalidInputError(f"no drop zone for colour {color!r}; zones: {sorted(zones)}")
    name = f"cube_{color}"
    T = object_pose(engine, name)
    dist = float(np.linalg.norm(T[:2, 3] - np.asarray(zones[color])))
    lin, ang = object_velocity(engine, name)
    at_rest = lin < REST_LINEAR_M_S and ang < REST_ANGULAR_RAD_S
    reasons = []
    if dist > tolerance_m:
        reasons.append(f"{dist * 1000:.0f} mm from the zone centre (> {tolerance_m * 1000:.0f} mm)")
    if not at_rest:
        reasons.append("moving")
    return CubePlaceResult(not reasons, dist, at_rest, tuple(reasons))
