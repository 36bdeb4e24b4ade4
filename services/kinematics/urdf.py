"""URDF text for the supported arms, with simple collision geometry and a configurable tool.

- Nova5: the vendor's joint table (spec §6.2, ``dobot_rviz/urdf/nova5_robot.urdf``) copied
  verbatim — origins, axes, position limits — so joint zero and signs equal the
  controller's. The vendor gives no velocity limits; ours (``config/robots/limits.yaml``)
  go into the ``velocity`` attributes.
- UR5e / UR3: built from the nominal DH table (spec §7); the link frames *are* the DH
  frames, so the flange (``tool0``) equals the DH end frame. ``base_link`` here is UR's
  controller ``base`` frame (the frame of URScript poses and the teach pendant), which is
  ROS ur_description's ``base_link`` turned 180° about z: poses from ROS tools need that turn.
  UR3 wrist 3 is limited to ±2π like every other UR wrist joint (see robot_models).

:func:`arm_joints` is the one joint table: the URDF text is written from it and the closed-form
IK (:mod:`services.kinematics.analytic`) solves the chain it describes, with the numbers exactly
as written in the file (15 significant digits), so both see the same robot.

Collision geometry is one capsule per straight piece of each link (the ``d`` and ``a``
offsets of the DH table, mapped into the URDF link frame), written as URDF
``<cylinder>`` elements because URDF has no capsule; :mod:`services.kinematics.collision`
checks them as capsules (rounded ends, slightly conservative). Inertials are rough
solid-cylinder estimates, marked as such: no vendor data was available.

The tool (:class:`~services.kinematics.tool.ToolGeometry`): a fixed ``gripper`` link on the flange carrying
the palm and finger collision shapes, and a ``tool_tip`` frame (fixed joint) at the configurable offset.
``config/robots/*.urdf`` are generated from here with the default tool
(``python -m services.kinematics.urdf``); a test checks they are current.
"""

from __future__ import annotations

import math
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from services.kinematics.robot_models import ROBOTS_DIR, RobotSpec, get_robot
from services.kinematics.tool import ToolGeometry

Array = np.ndarray

# Capsule radius per link (m), base first; sized to the arms' housings.
LINK_RADII_M: dict[str, tuple[float, ...]] = {
    "nova5": (0.080, 0.065, 0.060, 0.050, 0.045, 0.045, 0.040),
    "ur5e": (0.080, 0.065, 0.060, 0.050, 0.045, 0.045, 0.040),
    "ur3": (0.065, 0.050, 0.045, 0.040, 0.035, 0.035, 0.032),
}
# Rough link masses (kg), base first — estimates for the physics twin, not vendor data.
LINK_MASSES_KG: dict[str, tuple[float, ...]] = {
    "nova5": (4.0, 3.5, 6.0, 2.5, 1.2, 1.2, 0.4),
    "ur5e": (4.0, 3.7, 8.4, 2.3, 1.2, 1.2, 0.25),
    "ur3": (2.0, 2.0, 3.4, 1.3, 0.8, 0.8, 0.35),
}
BASE_HEIGHT_M = 0.06  # fixed base capsule axis, from the mounting face up (plus its radius)


# --- vendor Nova5 joint table (spec §6.2, verbatim) -----------------------------------------------
NOVA5_JOINTS: tuple[
    tuple[str, str, str, tuple[float, ...], tuple[float, ...], tuple[float, ...], float, float], ...
] = (
    (
        "joint1",
        "base_link",
        "Link1",
        (0, 0, 0.240000000000178),
        (0, 0, 0),
        (0, 0, 0.999999999999855),
        -6.28,
        6.28,
    ),
    (
        "joint2",
        "Link1",
        "Link2",
        (0, 0, 0),
        (-1.57080287682252, 1.53586622836832, 3.14159265358979),
        (0, 0, 1),
        -3.14,
        3.14,
    ),
    (
        "joint3",
        "Link2",
        "Link3",
        (-0.399756009268664, -0.0139690033141953, 0),
        (0, 0, 0),
        (0, 0, 1),
        -2.79,
        2.79,
    ),
    (
        "joint4",
        "Link3",
        "Link4",
        (-0.329798707647103, -0.0115244277211674, 0.134999532858734),
        (0, 0, -1.53586622840712),
        (0, 0, 1),
        -6.28,
        6.28,
    ),
    ("joint5", "Link4", "Link5", (0, -0.12, 0), (1.5708, 0, 0), (0, 0, 1), -6.28, 6.28),
    ("joint6", "Link5", "Link6", (0, 0.088328, 0), (-1.5708, 0, 0), (0, 0, 1), -6.28, 6.28),
)
UR_LINKS = (
    "base_link",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
)


def link_names(spec: RobotSpec) -> tuple[str, ...]:
    """URDF link names, base first, one per joint after it."""
    if spec.name == "nova5":
        return ("base_link", *(j[2] for j in NOVA5_JOINTS))
    return UR_LINKS


def flange_link(spec: RobotSpec) -> str:
    return "Link6" if spec.name == "nova5" else "tool0"


def _fmt(v: float) -> str:
    s = f"{float(v):.15g}"
    return "0" if s in ("-0", "0") else s


def _written(v: ArrayLike) -> tuple[float, ...]:
    """Values as the URDF text gives them back (15 significant digits)."""
    return tuple(float(_fmt(x)) for x in np.ravel(v))


@dataclass(frozen=True)
class JointOrigin:
    """One URDF joint as written: origin (m, rad rpy) in the parent link; ``axis`` None when fixed."""

    name: str
    parent: str
    child: str
    xyz: tuple[float, ...]
    rpy: tuple[float, ...]
    axis: tuple[float, ...] | None
    lower: float = 0.0
    upper: float = 0.0

    def T_parent_child(self) -> Array:
        """The origin transform (the joint at zero), with URDF's rpy convention Rz(y) Ry(p) Rx(r)."""
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("xyz", self.rpy).as_matrix()
        T[:3, 3] = self.xyz
        return T


def arm_joints(spec: RobotSpec) -> tuple[JointOrigin, ...]:
    """The six arm joints, then (UR) the flange's fixed joint to ``tool0``; the Nova5's flange is Link6."""
    if spec.name == "nova5":
        return tuple(
            JointOrigin(n, p, c, _written(xyz), _written(rpy), _written(axis), *_written((lo, hi)))
            for n, p, c, xyz, rpy, axis, lo, hi in NOVA5_JOINTS
        )
    names = link_names(spec)
    joints = []
    fixed_prev = np.eye(4)
    for i in range(spec.dof):
        Rz = np.eye(4)
        Rz[:3, :3] = Rotation.from_euler("z", spec.theta_offset[i]).as_matrix()
        T = fixed_prev @ Rz
        lower, upper = _written((spec.lower[i], spec.upper[i]))
        joints.append(
            JointOrigin(
                spec.joint_names[i],
                names[i],
                names[i + 1],
                _written(T[:3, 3]),
                _written(_rpy(T[:3, :3])),
                (0.0, 0.0, 1.0),
                lower,
                upper,
            )
        )
        fixed_prev = _dh(spec, i, 0.0)
    flange = JointOrigin(
        "flange_fixed",
        names[-1],
        "tool0",
        _written(fixed_prev[:3, 3]),
        _written(_rpy(fixed_prev[:3, :3])),
        None,
    )
    return (*joints, flange)


def _vec(v: ArrayLike) -> str:
    return " ".join(_fmt(x) for x in np.ravel(v))


def _rpy(R: Array) -> Array:
    with warnings.catch_warnings():
        # pitch ±90° (gimbal lock) is fine: scipy returns an equivalent rpy with yaw 0
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(R).as_euler("xyz")


def _dh(spec: RobotSpec, i: int, theta: float) -> Array:
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(spec.alpha[i]), np.sin(spec.alpha[i])
    return np.array(
        [
            [ct, -st * ca, st * sa, spec.a[i] * ct],
            [st, ct * ca, -ct * sa, spec.a[i] * st],
            [0.0, sa, ca, spec.d[i]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _dh_frames(spec: RobotSpec, q: Array) -> list[Array]:
    """Base (frame 0) and DH frames 1..6 for joints q."""
    frames = [np.eye(4)]
    for i in range(spec.dof):
        frames.append(frames[-1] @ _dh(spec, i, q[i] + spec.theta_offset[i]))
    return frames


def _vendor_link_frames(q: Array) -> list[Array]:
    """Nova5 URDF link frames (base_link, Link1..Link6) for joints q, straight from the joint table."""
    frames = [np.eye(4)]
    for k, (_n, _p, _c, xyz, rpy, axis, _lo, _hi) in enumerate(NOVA5_JOINTS):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
        T[:3, 3] = xyz
        R = np.eye(4)
        R[:3, :3] = Rotation.from_rotvec(np.asarray(axis) / np.linalg.norm(axis) * q[k]).as_matrix()
        frames.append(frames[-1] @ T @ R)
    return frames


def _ur_link_frames(spec: RobotSpec, q: Array) -> list[Array]:
    """UR URDF link frames: link i turns with joint i about z of DH frame i-1."""
    dh = _dh_frames(spec, q)
    frames = [np.eye(4)]
    for i in range(spec.dof):
        Rz = np.eye(4)
        Rz[:3, :3] = Rotation.from_euler("z", q[i] + spec.theta_offset[i]).as_matrix()
        frames.append(dh[i] @ Rz)
    return frames


def link_segments(spec: RobotSpec) -> list[list[tuple[Array, Array]]]:
    """Per link (base first), the straight pieces (start, end) in that link's URDF frame."""
    q0 = np.zeros(spec.dof)
    dh = _dh_frames(spec, q0)
    urdf_frames = _vendor_link_frames(q0) if spec.name == "nova5" else _ur_link_frames(spec, q0)
    # the base capsule stays clear of the upper arm's capsule around the J2 axis
    radii = LINK_RADII_M[spec.name]
    base_top = max(0.0, min(BASE_HEIGHT_M, float(spec.d[0]) - radii[0] - radii[2] - 0.01))
    segments: list[list[tuple[Array, Array]]] = [[(np.zeros(3), np.array([0.0, 0.0, base_top]))]]
    for i in range(1, spec.dof + 1):
        # the link between joint i and joint i+1 is rigid with DH frame i; its pieces run from
        # the origin of frame i-1 along z_{i-1} by d_i, then along x_i by a_i
        T_link_world = np.linalg.inv(urdf_frames[i])
        p_prev = dh[i - 1][:3, 3]
        p_elbow = p_prev + dh[i - 1][:3, :3] @ np.array([0.0, 0.0, spec.d[i - 1]])
        p_end = dh[i][:3, 3]
        pieces = []
        for a, b in ((p_prev, p_elbow), (p_elbow, p_end)):
            if np.linalg.norm(b - a) > 1e-6:
                pieces.append(((T_link_world @ np.append(a, 1))[:3], (T_link_world @ np.append(b, 1))[:3]))
        segments.append(pieces)
    return segments


def _cylinder_between(a: Array, b: Array) -> tuple[Array, Array, float]:
    """Origin xyz, rpy and length of a URDF cylinder (axis z) spanning a → b."""
    axis = b - a
    length = float(np.linalg.norm(axis))
    z = axis / length
    # a rotation taking +z to the piece's direction: about the axis z × dir by the angle between them
    cross = np.cross([0.0, 0.0, 1.0], z)
    angle = math.atan2(float(np.linalg.norm(cross)), float(z[2]))
    rotvec = (
        cross / np.linalg.norm(cross) * angle
        if np.linalg.norm(cross) > 1e-12
        else (np.array([math.pi, 0.0, 0.0]) if z[2] < 0 else np.zeros(3))
    )
    rot = Rotation.from_rotvec(rotvec).as_matrix()
    rpy = _rpy(rot)
    return np.round((a + b) / 2, 9), np.round(rpy, 9), round(length, 9)


def _collision_xml(name: str, xyz: ArrayLike, rpy: ArrayLike, geometry: str) -> str:
    return (
        f'    <collision name="{name}">\n'
        f'      <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'
        f"      <geometry>{geometry}</geometry>\n"
        f"    </collision>\n"
    )


def _link_xml(name: str, pieces: list[tuple[Array, Array]], radius: float, mass: float) -> str:
    body = ""
    pieces = [(a, b) for a, b in pieces if float(np.linalg.norm(b - a)) > 1e-6] or (
        [(pieces[0][0], pieces[0][0] + np.array([0.0, 0.0, 1e-3]))] if pieces else []
    )
    main = max(pieces, key=lambda ab: float(np.linalg.norm(ab[1] - ab[0]))) if pieces else None
    if main is not None:
        xyz, rpy, length = _cylinder_between(*main)
        ixx = mass * (3 * radius**2 + length**2) / 12
        izz = mass * radius**2 / 2
        body += (
            "    <inertial>  <!-- rough solid-cylinder estimate, not vendor data -->\n"
            f'      <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'
            f'      <mass value="{_fmt(mass)}"/>\n'
            f'      <inertia ixx="{_fmt(ixx)}" ixy="0" ixz="0" iyy="{_fmt(ixx)}" iyz="0" izz="{_fmt(izz)}"/>\n'
            "    </inertial>\n"
        )
    for k, (a, b) in enumerate(pieces):
        xyz, rpy, length = _cylinder_between(a, b)
        body += _collision_xml(
            f"{name}_c{k}", xyz, rpy, f'<cylinder radius="{_fmt(radius)}" length="{_fmt(length)}"/>'
        )
    return f'  <link name="{name}">\n{body}  </link>\n'


def _joint_xml(
    name: str,
    parent: str,
    child: str,
    xyz: ArrayLike,
    rpy: ArrayLike,
    axis: ArrayLike | None,
    lower: float = 0.0,
    upper: float = 0.0,
    velocity: float = 0.0,
) -> str:
    kind = "fixed" if axis is None else "revolute"
    out = (
        f'  <joint name="{name}" type="{kind}">\n    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
        f'    <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'
    )
    if axis is not None:
        out += (
            f'    <axis xyz="{_vec(axis)}"/>\n'
            f'    <limit lower="{_fmt(lower)}" upper="{_fmt(upper)}" effort="0" velocity="{_fmt(velocity)}"/>\n'
        )
    return out + "  </joint>\n"


def _tool_xml(flange: str, tool: ToolGeometry) -> str:
    fingers_z = tool.finger_center_z()
    palm = (
        _collision_xml(
            "gripper_palm",
            [0.0, 0.0, tool.palm_length / 2],
            [0.0, 0.0, 0.0],
            f'<cylinder radius="{_fmt(tool.palm_radius)}" length="{_fmt(tool.palm_length)}"/>',
        )
        if tool.palm_length > 0
        else ""
    )
    fingers = _collision_xml(
        "gripper_fingers", [0.0, 0.0, fingers_z], [0.0, 0.0, 0.0], f'<box size="{_vec(tool.finger_box)}"/>'
    )
    return (
        f'  <link name="gripper">\n{palm}{fingers}  </link>\n'
        + _joint_xml("gripper_mount", flange, "gripper", [0, 0, 0], [0, 0, 0], None)
        + '  <link name="tool_tip"/>\n'
        + _joint_xml("tool_tip_joint", flange, "tool_tip", tool.tip_xyz, tool.tip_rpy, None)
    )


def robot_urdf(spec: RobotSpec, tool: ToolGeometry | None = None) -> str:
    """The URDF text of ``spec`` with ``tool`` (default: :class:`ToolGeometry`)."""
    tool = tool or ToolGeometry()
    names = link_names(spec)
    radii = LINK_RADII_M[spec.name]
    masses = LINK_MASSES_KG[spec.name]
    segments = link_segments(spec)
    parts = [
        '<?xml version="1.0"?>\n',
        f"<!-- {spec.name}: generated by services/kinematics/urdf.py (python -m services.kinematics.urdf); do not edit.\n",
    ]
    if spec.name == "nova5":
        parts.append(
            "     Joint origins, axes and position limits: the vendor URDF (Dobot-Arm/DOBOT_6Axis_ROS2_V4\n"
            "     dobot_rviz/urdf/nova5_robot.urdf) verbatim. Velocity limits (rad/s) are ours, not the\n"
            "     vendor's (it gives 0): see config/robots/limits.yaml. -->\n"
        )
    else:
        parts.append(
            "     Link frames are the nominal DH frames (UniversalRobots default_kinematics.yaml). base_link is\n"
            "     UR's controller base frame (URScript poses), i.e. ROS ur_description's base_link turned 180 deg\n"
            "     about z. Wrist 3 is limited to +-2 pi (a revolute joint, like the other wrist joints). -->\n"
        )
    parts.append(f'<robot name="{spec.name}">\n')
    for k, name in enumerate(names):
        parts.append(_link_xml(name, segments[k], radii[k], masses[k]))
    for k, j in enumerate(arm_joints(spec)):
        if j.axis is None:
            parts.append(f'  <link name="{j.child}"/>\n')
        velocity = spec.max_velocity[k] if j.axis is not None else 0.0
        parts.append(_joint_xml(j.name, j.parent, j.child, j.xyz, j.rpy, j.axis, j.lower, j.upper, velocity))
    parts.append(_tool_xml(flange_link(spec), tool))
    parts.append("</robot>\n")
    return "".join(parts)


def urdf_path(name: str) -> Path:
    return ROBOTS_DIR / f"{name}.urdf"


def write_default_urdfs() -> list[Path]:
    paths = []
    for name in ("nova5", "ur5e", "ur3"):
        path = urdf_path(name)
        path.write_text(robot_urdf(get_robot(name)))
        paths.append(path)
    return paths


def stale_urdfs() -> list[str]:
    """Names of committed URDF files that differ from what this module generates now."""
    return [
        n
        for n in ("nova5", "ur5e", "ur3")
        if not urdf_path(n).exists() or urdf_path(n).read_text() != robot_urdf(get_robot(n))
    ]


if __name__ == "__main__":
    for p in write_default_urdfs():
        print(f"wrote {p}")
    sys.exit(0)
