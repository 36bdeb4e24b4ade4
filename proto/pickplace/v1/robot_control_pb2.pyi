from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable
from typing import ClassVar as _ClassVar, Optional as _Optional

DESCRIPTOR: _descriptor.FileDescriptor

class Empty(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class JointStates(_message.Message):
    __slots__ = ("positions", "velocities", "efforts", "timestamp")
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    VELOCITIES_FIELD_NUMBER: _ClassVar[int]
    EFFORTS_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    positions: _containers.RepeatedScalarFieldContainer[float]
    velocities: _containers.RepeatedScalarFieldContainer[float]
    efforts: _containers.RepeatedScalarFieldContainer[float]
    timestamp: int
    def __init__(self, positions: _Optional[_Iterable[float]] = ..., velocities: _Optional[_Iterable[float]] = ..., efforts: _Optional[_Iterable[float]] = ..., timestamp: _Optional[int] = ...) -> None: ...

class JointPositions(_message.Message):
    __slots__ = ("positions", "max_velocity", "max_acceleration")
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    MAX_VELOCITY_FIELD_NUMBER: _ClassVar[int]
    MAX_ACCELERATION_FIELD_NUMBER: _ClassVar[int]
    positions: _containers.RepeatedScalarFieldContainer[float]
    max_velocity: float
    max_acceleration: float
    def __init__(self, positions: _Optional[_Iterable[float]] = ..., max_velocity: _Optional[float] = ..., max_acceleration: _Optional[float] = ...) -> None: ...

class MoveResponse(_message.Message):
    __slots__ = ("success", "message", "execution_time")
    SUCCESS_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    EXECUTION_TIME_FIELD_NUMBER: _ClassVar[int]
    success: bool
    message: str
    execution_time: float
    def __init__(self, success: _Optional[bool] = ..., message: _Optional[str] = ..., execution_time: _Optional[float] = ...) -> None: ...

class GraspPose(_message.Message):
    __slots__ = ("x", "y", "z", "qx", "qy", "qz", "qw", "approach_distance", "lift_distance")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    QX_FIELD_NUMBER: _ClassVar[int]
    QY_FIELD_NUMBER: _ClassVar[int]
    QZ_FIELD_NUMBER: _ClassVar[int]
    QW_FIELD_NUMBER: _ClassVar[int]
    APPROACH_DISTANCE_FIELD_NUMBER: _ClassVar[int]
    LIFT_DISTANCE_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    qx: float
    qy: float
    qz: float
    qw: float
    approach_distance: float
    lift_distance: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ..., qx: _Optional[float] = ..., qy: _Optional[float] = ..., qz: _Optional[float] = ..., qw: _Optional[float] = ..., approach_distance: _Optional[float] = ..., lift_distance: _Optional[float] = ...) -> None: ...

class GraspResponse(_message.Message):
    __slots__ = ("success", "message", "object_detected")
    SUCCESS_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    OBJECT_DETECTED_FIELD_NUMBER: _ClassVar[int]
    success: bool
    message: str
    object_detected: bool
    def __init__(self, success: _Optional[bool] = ..., message: _Optional[str] = ..., object_detected: _Optional[bool] = ...) -> None: ...

class Metrics(_message.Message):
    __slots__ = ("cycle_time", "success_rate", "picks_today")
    CYCLE_TIME_FIELD_NUMBER: _ClassVar[int]
    SUCCESS_RATE_FIELD_NUMBER: _ClassVar[int]
    PICKS_TODAY_FIELD_NUMBER: _ClassVar[int]
    cycle_time: float
    success_rate: float
    picks_today: int
    def __init__(self, cycle_time: _Optional[float] = ..., success_rate: _Optional[float] = ..., picks_today: _Optional[int] = ...) -> None: ...
