from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Header(_message.Message):
    __slots__ = ("stamp_ns", "frame_id", "seq")
    STAMP_NS_FIELD_NUMBER: _ClassVar[int]
    FRAME_ID_FIELD_NUMBER: _ClassVar[int]
    SEQ_FIELD_NUMBER: _ClassVar[int]
    stamp_ns: int
    frame_id: str
    seq: int
    def __init__(self, stamp_ns: _Optional[int] = ..., frame_id: _Optional[str] = ..., seq: _Optional[int] = ...) -> None: ...

class JointState(_message.Message):
    __slots__ = ("header", "name", "position", "velocity", "effort", "robot_mode", "current_command_id", "tcp_pose", "digital_outputs", "digital_inputs", "tcp_force", "source_stamp_ns")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    NAME_FIELD_NUMBER: _ClassVar[int]
    POSITION_FIELD_NUMBER: _ClassVar[int]
    VELOCITY_FIELD_NUMBER: _ClassVar[int]
    EFFORT_FIELD_NUMBER: _ClassVar[int]
    ROBOT_MODE_FIELD_NUMBER: _ClassVar[int]
    CURRENT_COMMAND_ID_FIELD_NUMBER: _ClassVar[int]
    TCP_POSE_FIELD_NUMBER: _ClassVar[int]
    DIGITAL_OUTPUTS_FIELD_NUMBER: _ClassVar[int]
    DIGITAL_INPUTS_FIELD_NUMBER: _ClassVar[int]
    TCP_FORCE_FIELD_NUMBER: _ClassVar[int]
    SOURCE_STAMP_NS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    name: _containers.RepeatedScalarFieldContainer[str]
    position: _containers.RepeatedScalarFieldContainer[float]
    velocity: _containers.RepeatedScalarFieldContainer[float]
    effort: _containers.RepeatedScalarFieldContainer[float]
    robot_mode: int
    current_command_id: int
    tcp_pose: Pose
    digital_outputs: int
    digital_inputs: int
    tcp_force: _containers.RepeatedScalarFieldContainer[float]
    source_stamp_ns: int
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., name: _Optional[_Iterable[str]] = ..., position: _Optional[_Iterable[float]] = ..., velocity: _Optional[_Iterable[float]] = ..., effort: _Optional[_Iterable[float]] = ..., robot_mode: _Optional[int] = ..., current_command_id: _Optional[int] = ..., tcp_pose: _Optional[_Union[Pose, _Mapping]] = ..., digital_outputs: _Optional[int] = ..., digital_inputs: _Optional[int] = ..., tcp_force: _Optional[_Iterable[float]] = ..., source_stamp_ns: _Optional[int] = ...) -> None: ...

class Pose(_message.Message):
    __slots__ = ("x", "y", "z", "qx", "qy", "qz", "qw")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    QX_FIELD_NUMBER: _ClassVar[int]
    QY_FIELD_NUMBER: _ClassVar[int]
    QZ_FIELD_NUMBER: _ClassVar[int]
    QW_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    qx: float
    qy: float
    qz: float
    qw: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ..., qx: _Optional[float] = ..., qy: _Optional[float] = ..., qz: _Optional[float] = ..., qw: _Optional[float] = ...) -> None: ...

class Point(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class PoseStamped(_message.Message):
    __slots__ = ("header", "pose")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    POSE_FIELD_NUMBER: _ClassVar[int]
    header: Header
    pose: Pose
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., pose: _Optional[_Union[Pose, _Mapping]] = ...) -> None: ...

class JointTrajectoryPoint(_message.Message):
    __slots__ = ("positions", "velocities", "accelerations", "time_from_start_s")
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    VELOCITIES_FIELD_NUMBER: _ClassVar[int]
    ACCELERATIONS_FIELD_NUMBER: _ClassVar[int]
    TIME_FROM_START_S_FIELD_NUMBER: _ClassVar[int]
    positions: _containers.RepeatedScalarFieldContainer[float]
    velocities: _containers.RepeatedScalarFieldContainer[float]
    accelerations: _containers.RepeatedScalarFieldContainer[float]
    time_from_start_s: float
    def __init__(self, positions: _Optional[_Iterable[float]] = ..., velocities: _Optional[_Iterable[float]] = ..., accelerations: _Optional[_Iterable[float]] = ..., time_from_start_s: _Optional[float] = ...) -> None: ...

class JointTrajectory(_message.Message):
    __slots__ = ("header", "joint_names", "points")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    JOINT_NAMES_FIELD_NUMBER: _ClassVar[int]
    POINTS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    joint_names: _containers.RepeatedScalarFieldContainer[str]
    points: _containers.RepeatedCompositeFieldContainer[JointTrajectoryPoint]
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., joint_names: _Optional[_Iterable[str]] = ..., points: _Optional[_Iterable[_Union[JointTrajectoryPoint, _Mapping]]] = ...) -> None: ...

class CommandResponse(_message.Message):
    __slots__ = ("success", "message")
    SUCCESS_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    success: bool
    message: str
    def __init__(self, success: _Optional[bool] = ..., message: _Optional[str] = ...) -> None: ...

class ConfigUpdate(_message.Message):
    __slots__ = ("header", "patch_json", "updated")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    PATCH_JSON_FIELD_NUMBER: _ClassVar[int]
    UPDATED_FIELD_NUMBER: _ClassVar[int]
    header: Header
    patch_json: str
    updated: _containers.RepeatedScalarFieldContainer[str]
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., patch_json: _Optional[str] = ..., updated: _Optional[_Iterable[str]] = ...) -> None: ...
