"""Bus messages and frames → Foxglove messages, serialised once for the live view and the recording (pure).

Every function returns the payload bytes of one channel of :mod:`services.record.channels`. Frames:
``T_a_b`` maps points in frame b to frame a; a FrameTransform from parent ``a`` to child ``b`` carries
``T_a_b`` (the child's pose in the parent).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import cv2
import numpy as np
from foxglove.messages import (
    CameraCalibration,
    Color,
    CompressedImage,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    Log,
    LogLevel,
    Pose,
    Quaternion,
    RawImage,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    TextPrimitive,
    Timestamp,
    Vector3,
)
from pickplace.v1 import common_pb2, robot_pb2, vision_pb2
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError
from services.common.sensors import CameraIntrinsics
from services.dobot.codes import RobotMode, describe_alarm
from services.kinematics.robot_models import RobotSpec
from services.kinematics.tool import ToolGeometry
from services.kinematics.urdf import arm_joints, flange_link, link_names

Array = np.ndarray
BASE_FRAME = "base"  # the frame of every base-frame pose on the bus (detections, tool pose)
TOOL_FRAME = "tool_tip"


def timestamp(stamp_ns: int) -> Timestamp:
    sec, nsec = divmod(max(int(stamp_ns), 0), 1_000_000_000)
    return Timestamp(sec, nsec)


def _quat_xyzw(R: Array) -> Array:
    return np.asarray(Rotation.from_matrix(R).as_quat(), dtype=float)


def _qmul(a: Array, b: Array) -> Array:
    """Hamilton product of quaternions in (x, y, z, w) order."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _transform(stamp: Timestamp, parent: str, child: str, xyz: Array, q_xyzw: Array) -> FrameTransform:
    return FrameTransform(
        timestamp=stamp,
        parent_frame_id=parent,
        child_frame_id=child,
        translation=Vector3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
        rotation=Quaternion(x=float(q_xyzw[0]), y=float(q_xyzw[1]), z=float(q_xyzw[2]), w=float(q_xyzw[3])),
    )


@dataclass(frozen=True)
class _Joint:
    parent: str
    child: str
    xyz: Array
    q_origin: Array  # xyzw
    axis: Array | None


class LinkTransforms:
    """The URDF's tree as FrameTransforms: ``base → base_link``, every joint's parent → child at the
    measured joint angles (FK joint by joint, as the URDF writes it), the tool tip and the camera."""

    def __init__(
        self,
        spec: RobotSpec,
        tool: ToolGeometry,
        T_base_camera: Array | None = None,
        camera_frame: str = "camera",
    ):
        self.spec = spec
        self.root = link_names(spec)[0]
        self.camera_frame = camera_frame
        self.T_base_camera = None if T_base_camera is None else np.asarray(T_base_camera, dtype=float)
        joints = []
        for j in arm_joints(spec):
            T = j.T_parent_child()
            axis = None if j.axis is None else np.asarray(j.axis, dtype=float) / np.linalg.norm(j.axis)
            joints.append(_Joint(j.parent, j.child, T[:3, 3].copy(), _quat_xyzw(T[:3, :3]), axis))
        T_tool = tool.T_flange_tool()
        flange = flange_link(spec)
        joints.append(_Joint(flange, "gripper", np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), None))
        joints.append(_Joint(flange, TOOL_FRAME, T_tool[:3, 3].copy(), _quat_xyzw(T_tool[:3, :3]), None))
        self._joints = tuple(joints)
        self.n_moving = sum(j.axis is not None for j in joints)

    @property
    def frames(self) -> tuple[str, ...]:
        """Every child frame this tree names (the URDF links, the tool tip, the camera when calibrated)."""
        out = [self.root, *(j.child for j in self._joints)]
        if self.T_base_camera is not None:
            out.append(self.camera_frame)
        return tuple(out)

    def message(self, q: Array, stamp_ns: int) -> bytes:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n_moving,) or not np.all(np.isfinite(q)):
            raise InvalidInputError(f"joint state must hold {self.n_moving} finite angles, got {q.tolist()}")
        stamp = timestamp(stamp_ns)
        out = [_transform(stamp, BASE_FRAME, self.root, np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))]
        k = 0
        for j in self._joints:
            rot = j.q_origin
            if j.axis is not None:
                half = 0.5 * q[k]
                rot = _qmul(j.q_origin, np.array([*(j.axis * np.sin(half)), np.cos(half)]))
                k += 1
            out.append(_transform(stamp, j.parent, j.child, j.xyz, rot))
        if self.T_base_camera is not None:
            T = self.T_base_camera
            out.append(_transform(stamp, BASE_FRAME, self.camera_frame, T[:3, 3], _quat_xyzw(T[:3, :3])))
        return FrameTransforms(transforms=out).encode()


# ---------------------------------------------------------------------------- robot description
VISUAL_RGBA = "0.75 0.77 0.8 1"


def urdf_with_visuals(urdf: str) -> str:
    """The URDF with every collision shape also as a visual one: the project's URDFs carry collision
    geometry only, and Foxglove's 3D panel draws visuals."""
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as exc:
        raise InvalidInputError(f"robot description is not valid URDF XML: {exc}") from exc
    for link in root.iter("link"):
        if link.find("visual") is not None:
            continue
        for k, col in enumerate(link.findall("collision")):
            vis = ET.SubElement(link, "visual", {"name": f"{link.get('name')}_v{k}"})
            for child in col:
                vis.append(child)
            mat = ET.SubElement(vis, "material", {"name": "pickplace_grey"})
            ET.SubElement(mat, "color", {"rgba": VISUAL_RGBA})
            link.remove(col)
            link.append(col)  # keep the collision after its visual copy
    return ET.tostring(root, encoding="unicode")


def robot_description(urdf: str) -> bytes:
    return json.dumps({"data": urdf}).encode()


# ---------------------------------------------------------------------------- camera
def color_jpeg(color_rgb: Array, stamp_ns: int, frame_id: str, quality: int) -> bytes:
    ok, buf = cv2.imencode(
        ".jpg", cv2.cvtColor(color_rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality]
    )
    if not ok:
        raise InvalidInputError(f"cannot JPEG-encode a {color_rgb.shape} {color_rgb.dtype} image")
    return CompressedImage(
        timestamp=timestamp(stamp_ns), frame_id=frame_id, data=buf.tobytes(), format="jpeg"
    ).encode()


def depth_raw(depth_u16: Array, stamp_ns: int, frame_id: str) -> bytes:
    d = np.ascontiguousarray(depth_u16, dtype="<u2")
    h, w = d.shape
    return RawImage(
        timestamp=timestamp(stamp_ns),
        frame_id=frame_id,
        width=w,
        height=h,
        encoding="16UC1",
        step=2 * w,
        data=d.tobytes(),
    ).encode()


def camera_calibration(intr: CameraIntrinsics, stamp_ns: int, frame_id: str) -> bytes:
    fx, fy, cx, cy = intr.fx, intr.fy, intr.cx, intr.cy
    D = [float(v) for v in intr.distortion]
    return CameraCalibration(
        timestamp=timestamp(stamp_ns),
        frame_id=frame_id,
        width=int(intr.width),
        height=int(intr.height),
        distortion_model="plumb_bob" if len(D) in (0, 5) else "rational_polynomial",
        D=D or [0.0] * 5,
        K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    ).encode()


# ---------------------------------------------------------------------------- detections
LABEL_RGBA: dict[str, tuple[float, float, float, float]] = {
    "red": (0.9, 0.1, 0.1, 0.9),
    "green": (0.1, 0.75, 0.2, 0.9),
    "blue": (0.15, 0.3, 0.95, 0.9),
    "yellow": (0.95, 0.85, 0.1, 0.9),
    "black": (0.1, 0.1, 0.1, 0.9),
}
ROD_RGBA = (0.2, 0.2, 0.25, 0.95)
OBSTACLE_RGBA = (1.0, 0.55, 0.0, 0.35)
TEXT_RGBA = (1.0, 1.0, 1.0, 1.0)
UNKNOWN_RGBA = (0.6, 0.6, 0.6, 0.9)


def _color(rgba: tuple[float, float, float, float]) -> Color:
    return Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _pose(p: common_pb2.Pose, turn_xyzw: Array | None = None) -> Pose:
    q = np.array([p.qx, p.qy, p.qz, p.qw], dtype=float)
    if not np.any(q):
        q = np.array([0.0, 0.0, 0.0, 1.0])
    if turn_xyzw is not None:
        q = _qmul(q, turn_xyzw)
    return Pose(
        position=Vector3(x=p.x, y=p.y, z=p.z),
        orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
    )


def _text(x: float, y: float, z: float, text: str) -> TextPrimitive:
    return TextPrimitive(
        pose=Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(x=0, y=0, z=0, w=1)),
        billboard=True,
        font_size=14.0,
        scale_invariant=True,
        color=_color(TEXT_RGBA),
        text=text,
    )


# a rod's pose has x along its axis; a Foxglove cylinder's axis is its z: turn +90° about y
_ROD_TURN = np.array([0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)])


def scene_update(objs: vision_pb2.DetectedObjects, camera_frame: str, cube_size_m: float) -> bytes:
    """One SceneUpdate replacing the previous one: rods as cylinders, cubes as cubes in their colour,
    obstacle boxes translucent, each with a label; in the base frame when calibrated, else the camera's."""
    stamp = timestamp(objs.header.stamp_ns)
    entities = []
    for k, rod in enumerate(objs.rods):
        frame, pose = (BASE_FRAME, rod.pose_base) if rod.has_base else (camera_frame, rod.pose_camera)
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=frame,
                id=f"rod{k}",
                cylinders=[
                    CylinderPrimitive(
                        pose=_pose(pose, _ROD_TURN),
                        size=Vector3(x=rod.diameter_m, y=rod.diameter_m, z=rod.length_m),
                        bottom_scale=1.0,
                        top_scale=1.0,
                        color=_color(ROD_RGBA),
                    )
                ],
                texts=[_text(pose.x, pose.y, pose.z + 0.04, f"rod {rod.confidence:.2f} ({rod.method})")],
            )
        )
    for k, cube in enumerate(objs.cubes):
        frame, pose = (BASE_FRAME, cube.pose_base) if cube.has_base else (camera_frame, cube.pose_camera)
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=frame,
                id=f"cube{k}",
                cubes=[
                    CubePrimitive(
                        pose=_pose(pose),
                        size=Vector3(x=cube_size_m, y=cube_size_m, z=cube_size_m),
                        color=_color(LABEL_RGBA.get(cube.color_label, UNKNOWN_RGBA)),
                    )
                ],
                texts=[_text(pose.x, pose.y, pose.z + cube_size_m, f"cube {cube.color_label}")],
            )
        )
    for k, box in enumerate(objs.obstacles):
        frame, b = (BASE_FRAME, box.base) if box.has_base else (camera_frame, box.camera)
        lo = np.array([b.min.x, b.min.y, b.min.z])
        hi = np.array([b.max.x, b.max.y, b.max.z])
        c, size = (lo + hi) / 2, np.abs(hi - lo)
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=frame,
                id=f"obstacle{k}",
                cubes=[
                    CubePrimitive(
                        pose=Pose(
                            position=Vector3(x=c[0], y=c[1], z=c[2]),
                            orientation=Quaternion(x=0, y=0, z=0, w=1),
                        ),
                        size=Vector3(x=size[0], y=size[1], z=size[2]),
                        color=_color(OBSTACLE_RGBA),
                    )
                ],
                texts=[_text(c[0], c[1], hi[2] + 0.03, f"obstacle {box.color_label}".strip())],
            )
        )
    deletions = [SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)]
    return SceneUpdate(deletions=deletions, entities=entities).encode()


# ---------------------------------------------------------------------------- robot status, log
def robot_status_view(st: robot_pb2.RobotStatus) -> bytes:
    return json.dumps(
        {
            "connected": st.connected,
            "robot_model": st.robot_model,
            "mode": st.robot_mode,
            "mode_name": st.robot_mode_name or RobotMode.name_of(st.robot_mode),
            "enabled": st.enabled,
            "estop_active": st.estop_active,
            "gripper_closed": st.gripper_closed,
            "alarms": [{"id": int(a), "meaning": describe_alarm(int(a))} for a in st.alarms],
        }
    ).encode()


def robot_status_from_joints(js: common_pb2.JointState, robot_model: str) -> robot_pb2.RobotStatus:
    """What the joint-state stream alone tells of the robot (no alarm list: that needs GetErrorID)."""
    return robot_pb2.RobotStatus(
        connected=True,
        robot_model=robot_model,
        robot_mode=js.robot_mode,
        robot_mode_name=RobotMode.name_of(js.robot_mode),
        enabled=js.robot_mode in (RobotMode.ENABLE, RobotMode.RUNNING, RobotMode.SINGLE_MOVE),
    )


_LEVELS = ((40, LogLevel.Error), (30, LogLevel.Warning), (20, LogLevel.Info), (1, LogLevel.Debug))


def log_message(stamp_ns: int, levelno: int, name: str, message: str, file: str, line: int) -> bytes:
    level = (
        LogLevel.Fatal if levelno >= 50 else next((lv for n, lv in _LEVELS if levelno >= n), LogLevel.Unknown)
    )
    return Log(
        timestamp=timestamp(stamp_ns), level=level, message=message, name=name, file=file, line=line
    ).encode()
