"""MJCF of the cell, generated from the robot's DH table, the gripper settings and a scene.

Kinematics: body ``link{i}`` sits at ``D_{i-1} · Rz(offset_i)`` in its parent, where
``D_j = Tz(d_j) Tx(a_j) Rx(alpha_j)``, and turns by ``q_i`` about its z axis; the gripper body
sits at ``D_6`` in ``link6``. So the ``flange`` site is exactly ``analytic.fk(spec, q)``.

Geometry is simple (capsules along the DH segments, cylinders for the joint housings, boxes for
the gripper). Collision classes: ``robot`` geoms (arm, gripper) touch the environment and the
objects but not each other; ``env`` (table, obstacle) and ``object`` geoms touch everything.
Contact and solver settings come from :class:`TwinPhysicsSettings` — the one documented place.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from services.common.settings import GripperSettings, TwinCameraSettings, TwinPhysicsSettings
from services.kinematics.robot_models import RobotSpec
from services.sim.twin.randomization import Variation
from services.sim.twin.scene import COLORS_RGBA, Scene, SceneObject, hollow_tube_inertia

Array = np.ndarray

# --- names shared with the engine, camera and ground truth --------------------------------------
ARM_BODIES = tuple(f"link{i}" for i in range(1, 7))
GRIPPER_BODY = "gripper"
FINGER_JOINTS = ("finger_left", "finger_right")
PAD_GEOMS = ("pad_left", "pad_right")
GRIP_ACTUATOR = "gripper"
GRIP_TENDON = "grip"
FLANGE_SITE = "flange"
TOOL_SITE = "tool_tip"
FT_SITE = "ft_site"
FORCE_SENSOR = "wrist_force"
TORQUE_SENSOR = "wrist_torque"
CAMERA = "realsense"
TABLE_GEOM = "table"

# --- gripper geometry (m), in the flange frame: z out of the flange, jaws close along y ---------
PALM_TOP = 0.02  # adapter plate 0..0.02, palm below it
PALM_BOTTOM = 0.09
PALM_HALF = (0.035, 0.06)
PAD_HALF = (0.011, 0.002, 0.010)  # across the jaw, thickness, along the finger
FINGER_HALF_XY = (0.011, 0.005)
PALM_MASS_KG = 0.5
FINGER_MASS_KG = 0.05

# --- arm drive: per-model joint torque limits (N·m) and reflected motor inertia (kg·m²) ----------
TORQUE_LIMITS_NM = {
    "nova5": (150.0, 150.0, 150.0, 28.0, 28.0, 28.0),
    "ur5e": (150.0, 150.0, 150.0, 28.0, 28.0, 28.0),
    "ur3": (56.0, 56.0, 28.0, 12.0, 12.0, 12.0),
}
ARMATURE = (0.3, 0.3, 0.2, 0.05, 0.05, 0.05)
JOINT_DAMPING = 0.5  # N·m·s/rad: small, the PD does the work
LINK_RADIUS = (0.06, 0.055, 0.05, 0.045, 0.045, 0.04)
LINK_DENSITY = 1200.0  # kg/m³ over the capsule volume: ~15 kg arm


@dataclass(frozen=True)
class ArmGains:
    kp: tuple[float, ...]  # N·m/rad
    kv: tuple[float, ...]  # N·m·s/rad


def _f(*v: float) -> str:
    return " ".join(f"{float(x):.12g}" for x in v)


def _quat(R: Array) -> str:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return _f(w, x, y, z)


def dh_fixed(spec: RobotSpec, j: int) -> Array:
    """``Tz(d_j) Tx(a_j) Rx(alpha_j)``: the constant part of DH joint j's transform."""
    ca, sa = np.cos(spec.alpha[j]), np.sin(spec.alpha[j])
    return np.array(
        [[1, 0, 0, spec.a[j]], [0, ca, -sa, 0], [0, sa, ca, spec.d[j]], [0, 0, 0, 1]], dtype=float
    )


def _rz(t: float) -> Array:
    T = np.eye(4)
    T[:2, :2] = [[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]]
    return T


def camera_axes(cam: TwinCameraSettings) -> tuple[Array, Array, Array]:
    """(right, up, forward) unit vectors of the camera in the base frame (looking at ``look_at_m``)."""
    pos = np.asarray(cam.position_m, dtype=float)
    fwd = np.asarray(cam.look_at_m, dtype=float) - pos
    fwd /= np.linalg.norm(fwd)
    world_up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.999 else np.array([1.0, 0.0, 0.0])
    right = np.cross(fwd, world_up)
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return right, up, fwd


def camera_pose(camera: TwinCameraSettings, variation: Variation | None = None) -> Array:
    """T_base_camera of the optical frame (x right, y down, z forward): the nominal mount, or the true
    one of a varied world (offset in the base frame, rotation in the nominal optical frame)."""
    right, up, fwd = camera_axes(camera)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([right, -up, fwd])
    T[:3, 3] = camera.position_m
    if variation is not None:
        T[:3, :3] = T[:3, :3] @ variation.camera_rotation()
        T[:3, 3] += np.asarray(variation.camera_offset_m)
    return T


def _camera_attrs(camera: TwinCameraSettings, variation: Variation | None) -> dict[str, str]:
    """MJCF camera attributes: the nominal camera (fovy), or a varied one with its true pose and
    intrinsics (focal length and principal point in pixels; MuJoCo moves the principal point by minus
    ``principalpixel``)."""
    T = camera_pose(camera, variation)
    right, up = T[:3, 0], -T[:3, 1]
    attrs = {"name": CAMERA, "pos": _f(*T[:3, 3]), "xyaxes": _f(*right, *up)}
    if variation is None or (variation.focal_scale == 1.0 and variation.principal_offset_px == (0.0, 0.0)):
        attrs["fovy"] = _f(camera.fovy_deg)
        return attrs
    f_px = (camera.height / 2.0) / np.tan(np.radians(camera.fovy_deg) / 2.0) * variation.focal_scale
    pixel_m = 1e-5  # any sensor pitch: MuJoCo only uses the ratios
    du, dv = variation.principal_offset_px
    attrs.update(
        resolution=f"{camera.width} {camera.height}",
        sensorsize=_f(camera.width * pixel_m, camera.height * pixel_m),
        focalpixel=_f(f_px, f_px),
        principalpixel=_f(-du, -dv),
    )
    return attrs


def build_mjcf(
    spec: RobotSpec,
    gripper: GripperSettings,
    physics: TwinPhysicsSettings,
    camera: TwinCameraSettings,
    scene: Scene,
    gains: ArmGains | None = None,
    variation: Variation | None = None,
) -> str:
    """The cell as an MJCF string. Without ``gains`` the arm actuators get unit placeholders.

    ``physics`` carries the world's frictions and grip force; ``variation`` (a randomized world) moves
    the camera to its true mount and intrinsics and scales the lights."""
    light = 1.0 if variation is None else variation.light_scale
    root = ET.Element("mujoco", model=f"pickplace_cell_{spec.name}")
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    ET.SubElement(
        root,
        "option",
        timestep=_f(physics.timestep_s),
        integrator="implicitfast",
        cone=physics.cone,
        impratio=_f(physics.impratio),
        noslip_iterations=str(physics.noslip_iterations),
    )
    ET.SubElement(root, "statistic", extent="2", center="0.3 0 0.3")
    visual = ET.SubElement(root, "visual")
    ET.SubElement(
        visual, "global", offwidth=str(max(camera.width, 640)), offheight=str(max(camera.height, 480))
    )
    # near/far planes are fractions of the extent (2 m): 2 cm .. 10 m.
    ET.SubElement(visual, "map", znear="0.01", zfar="5")
    ET.SubElement(visual, "quality", shadowsize="2048")
    ET.SubElement(
        visual,
        "headlight",
        ambient=_f(*[0.35 * light] * 3),
        diffuse=_f(*[0.35 * light] * 3),
        specular=_f(*[0.05 * light] * 3),
    )

    asset = ET.SubElement(root, "asset")
    ET.SubElement(asset, "material", name="table", rgba="0.78 0.76 0.72 1", specular="0.1")
    ET.SubElement(
        asset,
        "material",
        name="rod_metal",
        rgba=_f(*COLORS_RGBA["black"]),
        # Polished black metal: full specular with a lobe wide enough to run along the tube as a stripe
        # (the camera's highlight model then brings it to what a colour sensor records under cell lights).
        specular="1",
        shininess="0.3",
        reflectance="0.05",
    )
    ET.SubElement(asset, "material", name="robot_white", rgba="0.92 0.92 0.9 1", specular="0.3")
    ET.SubElement(asset, "material", name="robot_dark", rgba="0.25 0.25 0.27 1", specular="0.3")
    ET.SubElement(asset, "material", name="obstacle", rgba="0.25 0.35 0.78 1", specular="0.1")

    default = ET.SubElement(root, "default")
    robot = ET.SubElement(default, "default", attrib={"class": "robot"})
    ET.SubElement(robot, "geom", contype="2", conaffinity="1", group="1", material="robot_white")
    ET.SubElement(robot, "joint", damping=_f(JOINT_DAMPING))
    env = ET.SubElement(default, "default", attrib={"class": "env"})
    ET.SubElement(
        env,
        "geom",
        contype="1",
        conaffinity="3",
        group="0",
        friction=_f(physics.table_friction, 0.005, 0.0001),
    )
    obj = ET.SubElement(default, "default", attrib={"class": "object"})
    ET.SubElement(
        obj,
        "geom",
        contype="1",
        conaffinity="3",
        group="2",
        condim="3",
        friction=_f(physics.object_friction, 0.005, 0.0001),
    )
    pad = ET.SubElement(default, "default", attrib={"class": "pad"})
    # priority 2: pad–object contacts use the pad's condim, friction and solref, not a mix of both (an
    # object with its own friction has priority 1 over the table and the other objects).
    # A stiff contact (time constant 2 timesteps, >= 4 ms): with the default 20 ms the light fingers
    # sink ~1.5 mm into the rod under a 10 N squeeze and the rod creeps out toward the fingertips.
    ET.SubElement(
        pad,
        "geom",
        contype="2",
        conaffinity="1",
        group="1",
        condim="4",
        priority="2",
        friction=_f(physics.pad_friction, physics.pad_torsional_friction_m, 0.0001),
        solref=_f(max(0.004, 2 * physics.timestep_s), 1.0),
        material="robot_dark",
    )

    world = ET.SubElement(root, "worldbody")
    ET.SubElement(
        world,
        "light",
        name="key",
        directional="true",
        pos="0.4 0.6 3",
        dir="-0.2 -0.3 -1",
        diffuse=_f(*[0.55 * light] * 3),
        specular=_f(*[0.2 * light] * 3),
        castshadow="true",
    )
    # The table top is the plane z = table_z_m of the base frame (0: the robot stands on it).
    ET.SubElement(
        world,
        "geom",
        name=TABLE_GEOM,
        type="plane",
        size="1.2 1.2 0.02",
        pos=_f(0, 0, scene.table_z_m),
        material="table",
        attrib={"class": "env"},
    )
    ET.SubElement(
        world,
        "geom",
        name="robot_base",
        type="cylinder",
        size="0.08 0.035",
        pos="0 0 0.035",
        material="robot_dark",
        attrib={"class": "robot"},
    )
    if scene.obstacle is not None:
        ob = scene.obstacle
        ET.SubElement(
            world,
            "geom",
            name=ob.name,
            type="box",
            size=_f(*ob.half_size_m),
            pos=_f(*ob.center_m),
            material="obstacle",
            attrib={"class": "env"},
        )
    ET.SubElement(world, "camera", _camera_attrs(camera, variation))

    _add_arm(world, spec, gripper)
    for o in scene.objects:
        _add_object(world, o)

    _add_drives(root, spec, gripper, physics, gains)
    sensor = ET.SubElement(root, "sensor")
    ET.SubElement(sensor, "force", name=FORCE_SENSOR, site=FT_SITE)
    ET.SubElement(sensor, "torque", name=TORQUE_SENSOR, site=FT_SITE)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode")


def _add_arm(world: ET.Element, spec: RobotSpec, gripper: GripperSettings) -> None:
    parent = world
    placement = np.eye(4)
    for i in range(spec.dof):
        T = placement @ _rz(spec.theta_offset[i])
        body = ET.SubElement(
            parent,
            "body",
            name=ARM_BODIES[i],
            pos=_f(*T[:3, 3]),
            quat=_quat(T[:3, :3]),
            gravcomp="1",
            childclass="robot",
        )
        lo, hi = spec.lower[i], spec.upper[i]
        jattrs = {"name": spec.joint_names[i], "axis": "0 0 1", "armature": _f(ARMATURE[i])}
        if hi - lo < 1e8:
            jattrs["range"] = _f(lo, hi)
        ET.SubElement(body, "joint", jattrs)
        r = LINK_RADIUS[i]
        a, d = spec.a[i], spec.d[i]
        start = np.zeros(3)
        if i == 0:  # the column stands on the base; keep its lower cap off the table
            start = np.array([0.0, 0.0, min(0.08, abs(d))])
        end = np.array([a, 0.0, d])
        if np.linalg.norm(end - start) > 1e-6:
            ET.SubElement(
                body,
                "geom",
                name=f"{ARM_BODIES[i]}_link",
                type="capsule",
                size=_f(r),
                fromto=_f(*start, *end),
                density=_f(LINK_DENSITY),
            )
        if i > 0:  # motor housing around the joint axis
            ET.SubElement(
                body,
                "geom",
                name=f"{ARM_BODIES[i]}_housing",
                type="cylinder",
                size=_f(r * 1.1, r),
                material="robot_dark",
                density=_f(LINK_DENSITY),
            )
        parent = body
        placement = dh_fixed(spec, i)
    _add_gripper(parent, placement, gripper)


def _add_gripper(link6: ET.Element, T_link6_flange: Array, gripper: GripperSettings) -> None:
    tcp = gripper.tcp_offset_m
    tip = tcp + PAD_HALF[2]
    body = ET.SubElement(
        link6,
        "body",
        name=GRIPPER_BODY,
        pos=_f(*T_link6_flange[:3, 3]),
        quat=_quat(T_link6_flange[:3, :3]),
        gravcomp="1",
        childclass="robot",
    )
    ET.SubElement(body, "site", name=FLANGE_SITE, size="0.005", group="4")
    ET.SubElement(body, "site", name=FT_SITE, size="0.004", group="4")
    ET.SubElement(body, "site", name=TOOL_SITE, pos=_f(0, 0, tcp), size="0.004", group="4")
    ET.SubElement(
        body,
        "geom",
        name="adapter",
        type="cylinder",
        size=_f(0.032, PALM_TOP / 2),
        pos=_f(0, 0, PALM_TOP / 2),
        material="robot_dark",
        mass="0.1",
    )
    ET.SubElement(
        body,
        "geom",
        name="palm",
        type="box",
        size=_f(PALM_HALF[0], PALM_HALF[1], (PALM_BOTTOM - PALM_TOP) / 2),
        pos=_f(0, 0, (PALM_TOP + PALM_BOTTOM) / 2),
        material="robot_dark",
        mass=_f(PALM_MASS_KG),
    )
    half_stroke = gripper.stroke_m / 2
    finger_half_z = (tip - PALM_BOTTOM) / 2
    for side, sign in (("left", 1.0), ("right", -1.0)):
        finger = ET.SubElement(body, "body", name=f"finger_{side}", gravcomp="1")
        ET.SubElement(
            finger,
            "joint",
            name=f"finger_{side}",
            type="slide",
            axis=_f(0, sign, 0),
            range=_f(0, half_stroke),
        )
        y_finger = sign * (2 * PAD_HALF[1] + FINGER_HALF_XY[1])
        ET.SubElement(
            finger,
            "geom",
            name=f"finger_{side}_link",
            type="box",
            size=_f(FINGER_HALF_XY[0], FINGER_HALF_XY[1], finger_half_z),
            pos=_f(0, y_finger, PALM_BOTTOM + finger_half_z),
            mass=_f(FINGER_MASS_KG * 0.8),
        )
        ET.SubElement(
            finger,
            "geom",
            name=f"pad_{side}",
            type="box",
            size=_f(*PAD_HALF),
            pos=_f(0, sign * PAD_HALF[1], tcp),
            mass=_f(FINGER_MASS_KG * 0.2),
            attrib={"class": "pad"},
        )


def _add_object(world: ET.Element, o: SceneObject) -> None:
    body = ET.SubElement(world, "body", name=o.name, pos=_f(*o.position_m), quat=_f(*o.quat_wxyz))
    ET.SubElement(body, "freejoint", name=f"{o.name}_free")
    if o.kind == "rod":
        r, length = o.size_m[0] / 2, o.size_m[2]
        i_perp, i_axial = hollow_tube_inertia(o.mass_kg, r, o.inner_radius_m, length)
        ET.SubElement(
            body, "inertial", pos="0 0 0", mass=_f(o.mass_kg), diaginertia=_f(i_perp, i_perp, i_axial)
        )
        # A cylinder (flat ends): a capsule can never stand.
        attrs = {
            "name": f"{o.name}_geom",
            "type": "cylinder",
            "size": _f(r, length / 2),
            "material": "rod_metal",
            "class": "object",
        }
        if o.friction is not None:  # its own friction wins over the table's (the pads' wins over it)
            attrs.update(friction=_f(o.friction, 0.005, 0.0001), priority="1")
        ET.SubElement(body, "geom", attrs)
    else:
        ET.SubElement(
            body,
            "geom",
            name=f"{o.name}_geom",
            type="box",
            size=_f(*(s / 2 for s in o.size_m)),
            mass=_f(o.mass_kg),
            rgba=_f(*COLORS_RGBA[o.color]),
            attrib={"class": "object"},
        )


def _add_drives(
    root: ET.Element,
    spec: RobotSpec,
    gripper: GripperSettings,
    physics: TwinPhysicsSettings,
    gains: ArmGains | None,
) -> None:
    tendon = ET.SubElement(root, "tendon")
    fixed = ET.SubElement(tendon, "fixed", name=GRIP_TENDON)
    for j in FINGER_JOINTS:
        ET.SubElement(fixed, "joint", joint=j, coef="1")
    # Coupled fingers (one motor, like real parallel grippers): right follows left.
    equality = ET.SubElement(root, "equality")
    ET.SubElement(equality, "joint", joint1=FINGER_JOINTS[1], joint2=FINGER_JOINTS[0], polycoef="0 1 0 0 0")

    act = ET.SubElement(root, "actuator")
    limits = TORQUE_LIMITS_NM.get(spec.name, TORQUE_LIMITS_NM["nova5"])
    for i, name in enumerate(spec.joint_names):
        kp = gains.kp[i] if gains else 1.0
        kv = gains.kv[i] if gains else 0.0
        # One actuator per joint carries both gains (position + velocity actuators in one default
        # class would overwrite each other); kv is integrated implicitly (implicitfast).
        ET.SubElement(
            act,
            "general",
            name=f"act_{name}",
            joint=name,
            gainprm=_f(kp),
            biastype="affine",
            biasprm=_f(0, -kp, -kv),
            forcerange=_f(-limits[i], limits[i]),
        )
    # Force-limited position control of the opening: squeeze = grip_force_n per finger when blocked.
    f = physics.grip_force_n
    kp_g = f / 0.002  # full force once the opening is 2 mm short of its target
    ET.SubElement(
        act,
        "general",
        name=GRIP_ACTUATOR,
        tendon=GRIP_TENDON,
        gainprm=_f(kp_g),
        biastype="affine",
        biasprm=_f(0, -kp_g, 0),
        forcerange=_f(-f, f),
        ctrlrange=_f(0, gripper.stroke_m),
    )
    # Finger speed = force / damping (the tendon's force acts on each finger).
    finger_damping = f / physics.finger_speed_m_s
    for j in FINGER_JOINTS:
        for el in root.iter("joint"):
            if el.get("name") == j:
                el.set("damping", _f(finger_damping))
