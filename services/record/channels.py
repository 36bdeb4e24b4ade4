"""The channels of the live view and of a recording: one table, topic → schema (pure).

Foxglove's well-known schemas where one fits (FrameTransforms, CompressedImage, RawImage,
CameraCalibration, SceneUpdate, Log); the project's own protobuf messages otherwise, embedded as a
``FileDescriptorSet`` so a file describes itself; a JSON schema for the robot status view (mode and
alarms with their meanings) and for the URDF (``std_msgs/String``-shaped, what Foxglove's URDF layer
reads from a topic).
"""

from __future__ import annotations

import enum
import json
from dataclasses import dataclass
from functools import cache
from typing import Any

import foxglove
from foxglove.messages import (
    CameraCalibration,
    CompressedImage,
    FrameTransforms,
    Log,
    RawImage,
    SceneUpdate,
)
from google.protobuf import descriptor_pb2
from google.protobuf.message import Message
from pickplace.v1 import common_pb2, task_pb2, vision_pb2


class Topic(enum.StrEnum):
    JOINT_STATES = "/joint_states"
    TF = "/tf"
    CAMERA_COLOR = "/camera/color"
    CAMERA_DEPTH = "/camera/depth"
    CAMERA_CALIBRATION = "/camera/calibration"
    DETECTIONS = "/detections"
    VISION_OBJECTS = "/vision/objects"
    PLAN = "/plan"
    PLANNING_SCENE = "/planning_scene"
    TASK_PLANS = "/task/plans"
    TASK_STATUS = "/task/status"
    PICK_EVENTS = "/pick_events"
    ROBOT_STATUS = "/robot/status"
    LOG = "/log"
    ROBOT_DESCRIPTION = "/robot_description"
    ROS2_JOINT_STATES = "/ros2/joint_states"  # the joint states as sensor_msgs/msg/JointState (record.ros2)


class Encoding(enum.StrEnum):
    PROTOBUF = "protobuf"
    JSON = "json"
    CDR = "cdr"  # ROS 2's serialisation, with a "ros2msg" schema


@dataclass(frozen=True)
class ChannelSpec:
    """One channel: its topic, message encoding and the schema (name, encoding, bytes) it carries."""

    topic: Topic
    message_encoding: Encoding
    schema_name: str
    schema_encoding: str  # "protobuf" (a FileDescriptorSet) | "jsonschema" | "ros2msg"
    schema_data: bytes
    what: str


def file_descriptor_set(message_type: type[Message]) -> bytes:
    """The message's .proto file and every file it imports, as one serialised FileDescriptorSet."""
    files: dict[str, Any] = {}

    def add(fd: Any) -> None:  # a FileDescriptor (pure-Python or upb)
        if fd.name in files:
            return
        for dep in fd.dependencies:
            add(dep)
        files[fd.name] = fd

    add(message_type.DESCRIPTOR.file)
    fds = descriptor_pb2.FileDescriptorSet()
    for fd in files.values():
        proto = fds.file.add()
        fd.CopyToProto(proto)
    return fds.SerializeToString()


ROBOT_STATUS_SCHEMA: dict[str, Any] = {
    "title": "pickplace.RobotStatusView",
    "type": "object",
    "properties": {
        "connected": {"type": "boolean"},
        "robot_model": {"type": "string"},
        "mode": {"type": "integer", "description": "Dobot RobotMode"},
        "mode_name": {"type": "string"},
        "enabled": {"type": "boolean"},
        "estop_active": {"type": "boolean"},
        "gripper_closed": {"type": "boolean"},
        "alarms": {
            "type": "array",
            "items": {
                "type": "object",
                "properties": {"id": {"type": "integer"}, "meaning": {"type": "string"}},
            },
        },
    },
}
# sensor_msgs/msg/JointState with the definitions it uses, concatenated as ROS 2 bags store them (ros2msg)
ROS2_JOINT_STATE = "sensor_msgs/msg/JointState"
ROS2_JOINT_STATE_MSGDEF = """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
STRING_SCHEMA: dict[str, Any] = {
    "title": "std_msgs/String",
    "type": "object",
    "properties": {"data": {"type": "string"}},
}


def _proto(topic: Topic, message_type: type[Message], what: str) -> ChannelSpec:
    return ChannelSpec(
        topic,
        Encoding.PROTOBUF,
        message_type.DESCRIPTOR.full_name,
        "protobuf",
        file_descriptor_set(message_type),
        what,
    )


def _foxglove(topic: Topic, message_type: Any, what: str) -> ChannelSpec:
    schema = message_type.get_schema()
    return ChannelSpec(topic, Encoding.PROTOBUF, schema.name, schema.encoding, bytes(schema.data), what)


def _json(topic: Topic, schema: dict[str, Any], what: str) -> ChannelSpec:
    return ChannelSpec(
        topic, Encoding.JSON, str(schema["title"]), "jsonschema", json.dumps(schema).encode(), what
    )


@cache
def channel_specs() -> dict[Topic, ChannelSpec]:
    specs = [
        _proto(Topic.JOINT_STATES, common_pb2.JointState, "every joint state of the driver (125 Hz)"),
        _foxglove(Topic.TF, FrameTransforms, "base, every URDF link from FK, tool tip, camera"),
        _foxglove(Topic.CAMERA_COLOR, CompressedImage, "colour frames, JPEG"),
        _foxglove(Topic.CAMERA_DEPTH, RawImage, "aligned depth, 16UC1 in depth units"),
        _foxglove(Topic.CAMERA_CALIBRATION, CameraCalibration, "intrinsics of the frames"),
        _foxglove(Topic.DETECTIONS, SceneUpdate, "rods, cubes and obstacle boxes vision reports"),
        _proto(Topic.VISION_OBJECTS, vision_pb2.DetectedObjects, "vision's DetectedObjects as published"),
        _foxglove(Topic.PLAN, SceneUpdate, "the planned tool path of the current cycle, as a line"),
        _foxglove(Topic.PLANNING_SCENE, SceneUpdate, "the collision boxes and table motion planned around"),
        _proto(Topic.TASK_PLANS, task_pb2.TaskPlan, "the task's plans as published: tool path and boxes"),
        _proto(Topic.TASK_STATUS, task_pb2.TaskStatus, "cycle state on every change and at 2 Hz"),
        _proto(Topic.PICK_EVENTS, task_pb2.PickEvent, "one per pick attempt"),
        _json(Topic.ROBOT_STATUS, ROBOT_STATUS_SCHEMA, "mode, e-stop, alarms with their meanings"),
        _foxglove(Topic.LOG, Log, "the Python logging of every service in the process"),
        _json(Topic.ROBOT_DESCRIPTION, STRING_SCHEMA, "the robot's URDF (with visuals) for the 3D panel"),
        ChannelSpec(
            Topic.ROS2_JOINT_STATES,
            Encoding.CDR,
            ROS2_JOINT_STATE,
            "ros2msg",
            ROS2_JOINT_STATE_MSGDEF.encode(),
            "the joint states for ROS 2 tools (record.ros2_joint_states)",
        ),
    ]
    return {s.topic: s for s in specs}


def open_channels(context: foxglove.Context) -> dict[Topic, foxglove.Channel]:
    """One foxglove channel per spec in ``context``: the live view and a recording each have their own
    context, so either can stop without the other."""
    return {
        spec.topic: foxglove.Channel(
            str(spec.topic),
            schema=foxglove.Schema(
                name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data
            ),
            message_encoding=str(spec.message_encoding),
            context=context,
        )
        for spec in channel_specs().values()
    }
