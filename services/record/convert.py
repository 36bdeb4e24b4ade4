"""Bus messages and frames → Foxglove messages, serialised once for the live view and the recording (pure).

Every function returns the payload bytes of one channel of :mod:`services.record.channels`. Frames:
``T_a_b`` maps points in frame b to frame a; a FrameTransform from parent ``a`` to child ``b`` carries
``T_a_b`` (the child's pose in the parent).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import cv2
import numpy as np
from foxglove.messages import (
    CameraCalibration,
    CompressedImage,
    FrameTransform,
    FrameTransforms,
    Log,
    LogLevel,
    Quaternion,
    RawImage,
    Timestamp,
    Vector3,
)
from pickplace.v1 import common_pb2, robot_pb2
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError
from services.common.sensors import CameraIntrinsics
from services.dobot.codes import RobotMode, describe_alarm
from services.kinematics.robot_models import RobotSpec
from services.kinematics.tool import ToolGeometry
from services.kinematics.urdf import arm_joints, flange_link, link_names
from services.record.channels import ROS2_JOINT_STATE, ROS2_JOINT_STATE_MSGDEF

Array = np.ndarray
BASE_FRAME = "base"  # the frame of every base-frame pose on the bus (detections, tool pose)
TOOL_FRAME = "tool_tip"


def timestamp(stamp_ns: int) -> Timestamp:
    sec, nsec = divmod(max(int(stamp_ns), 0), 1_000_000_000)
    return Timestamp(sec, nsec)


def _quat_xyzw(R: Array) -> Array:
    return np.asarray(Rotation.from_matrix(R).as_quat(), dtype=float)


def qmul(a: Array, b: Array) -> Array:
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
                rot = qmul(j.q_origin, np.array([*(j.axis * np.sin(half)), np.cos(half)]))
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


@cache
def _ros2_joint_state_encoder() -> Callable[[Any], bytes]:
    from mcap_ros2._dynamic import serialize_dynamic  # mcap-ros2-support's CDR encoder (its own writer's)

    return serialize_dynamic(ROS2_JOINT_STATE, ROS2_JOINT_STATE_MSGDEF)[ROS2_JOINT_STATE]


def ros2_joint_state(js: common_pb2.JointState) -> bytes:
    """A joint state as ROS 2 ``sensor_msgs/msg/JointState`` (CDR), stamped with its controller time when it
    has one; effort from the measured joint torques when the controller reports them."""
    sec, nsec = divmod(max(int(js.source_stamp_ns or js.header.stamp_ns), 0), 1_000_000_000)
    return _ros2_joint_state_encoder()(
        {
            "header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": js.header.frame_id},
            "name": list(js.name),
            "position": list(js.position),
            "velocity": list(js.velocity),
            "effort": list(js.effort),
        }
    )


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
