from pickplace.v1 import common_pb2 as _common_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class GetJointStatesRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class GetStatusRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class RobotStatus(_message.Message):
    __slots__ = ("robot_mode", "robot_mode_name", "enabled", "connected", "alarms", "joint_state", "gripper_closed", "estop_active", "robot_model")
    ROBOT_MODE_FIELD_NUMBER: _ClassVar[int]
    ROBOT_MODE_NAME_FIELD_NUMBER: _ClassVar[int]
    ENABLED_FIELD_NUMBER: _ClassVar[int]
    CONNECTED_FIELD_NUMBER: _ClassVar[int]
    ALARMS_FIELD_NUMBER: _ClassVar[int]
    JOINT_STATE_FIELD_NUMBER: _ClassVar[int]
    GRIPPER_CLOSED_FIELD_NUMBER: _ClassVar[int]
    ESTOP_ACTIVE_FIELD_NUMBER: _ClassVar[int]
    ROBOT_MODEL_FIELD_NUMBER: _ClassVar[int]
    robot_mode: int
    robot_mode_name: str
    enabled: bool
    connected: bool
    alarms: _containers.RepeatedScalarFieldContainer[int]
    joint_state: _common_pb2.JointState
    gripper_closed: bool
    estop_active: bool
    robot_model: str
    def __init__(self, robot_mode: _Optional[int] = ..., robot_mode_name: _Optional[str] = ..., enabled: _Optional[bool] = ..., connected: _Optional[bool] = ..., alarms: _Optional[_Iterable[int]] = ..., joint_state: _Optional[_Union[_common_pb2.JointState, _Mapping]] = ..., gripper_closed: _Optional[bool] = ..., estop_active: _Optional[bool] = ..., robot_model: _Optional[str] = ...) -> None: ...

class MoveJointsRequest(_message.Message):
    __slots__ = ("positions", "max_velocity", "max_acceleration", "speed_ratio", "linear")
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    MAX_VELOCITY_FIELD_NUMBER: _ClassVar[int]
    MAX_ACCELERATION_FIELD_NUMBER: _ClassVar[int]
    SPEED_RATIO_FIELD_NUMBER: _ClassVar[int]
    LINEAR_FIELD_NUMBER: _ClassVar[int]
    positions: _containers.RepeatedScalarFieldContainer[float]
    max_velocity: float
    max_acceleration: float
    speed_ratio: float
    linear: bool
    def __init__(self, positions: _Optional[_Iterable[float]] = ..., max_velocity: _Optional[float] = ..., max_acceleration: _Optional[float] = ..., speed_ratio: _Optional[float] = ..., linear: _Optional[bool] = ...) -> None: ...

class MoveResponse(_message.Message):
    __slots__ = ("success", "message", "execution_time", "final_positions", "stopped_early")
    SUCCESS_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    EXECUTION_TIME_FIELD_NUMBER: _ClassVar[int]
    FINAL_POSITIONS_FIELD_NUMBER: _ClassVar[int]
    STOPPED_EARLY_FIELD_NUMBER: _ClassVar[int]
    success: bool
    message: str
    execution_time: float
    final_positions: _containers.RepeatedScalarFieldContainer[float]
    stopped_early: bool
    def __init__(self, success: _Optional[bool] = ..., message: _Optional[str] = ..., execution_time: _Optional[float] = ..., final_positions: _Optional[_Iterable[float]] = ..., stopped_early: _Optional[bool] = ...) -> None: ...

class ExecuteTrajectoryRequest(_message.Message):
    __slots__ = ("trajectory", "servo_period_s", "force_guard", "continues")
    TRAJECTORY_FIELD_NUMBER: _ClassVar[int]
    SERVO_PERIOD_S_FIELD_NUMBER: _ClassVar[int]
    FORCE_GUARD_FIELD_NUMBER: _ClassVar[int]
    CONTINUES_FIELD_NUMBER: _ClassVar[int]
    trajectory: _common_pb2.JointTrajectory
    servo_period_s: float
    force_guard: ForceGuard
    continues: bool
    def __init__(self, trajectory: _Optional[_Union[_common_pb2.JointTrajectory, _Mapping]] = ..., servo_period_s: _Optional[float] = ..., force_guard: _Optional[_Union[ForceGuard, _Mapping]] = ..., continues: _Optional[bool] = ...) -> None: ...

class ForceGuard(_message.Message):
    __slots__ = ("force_drop_n", "direction")
    FORCE_DROP_N_FIELD_NUMBER: _ClassVar[int]
    DIRECTION_FIELD_NUMBER: _ClassVar[int]
    force_drop_n: float
    direction: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, force_drop_n: _Optional[float] = ..., direction: _Optional[_Iterable[float]] = ...) -> None: ...

class StreamJointStatesRequest(_message.Message):
    __slots__ = ("max_rate_hz",)
    MAX_RATE_HZ_FIELD_NUMBER: _ClassVar[int]
    max_rate_hz: float
    def __init__(self, max_rate_hz: _Optional[float] = ...) -> None: ...

class ExecuteGraspRequest(_message.Message):
    __slots__ = ("grasp_pose", "approach_distance", "lift_distance", "speed_scale")
    GRASP_POSE_FIELD_NUMBER: _ClassVar[int]
    APPROACH_DISTANCE_FIELD_NUMBER: _ClassVar[int]
    LIFT_DISTANCE_FIELD_NUMBER: _ClassVar[int]
    SPEED_SCALE_FIELD_NUMBER: _ClassVar[int]
    grasp_pose: _common_pb2.Pose
    approach_distance: float
    lift_distance: float
    speed_scale: float
    def __init__(self, grasp_pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., approach_distance: _Optional[float] = ..., lift_distance: _Optional[float] = ..., speed_scale: _Optional[float] = ...) -> None: ...

class SetGripperRequest(_message.Message):
    __slots__ = ("close", "release")
    CLOSE_FIELD_NUMBER: _ClassVar[int]
    RELEASE_FIELD_NUMBER: _ClassVar[int]
    close: bool
    release: bool
    def __init__(self, close: _Optional[bool] = ..., release: _Optional[bool] = ...) -> None: ...

class GripperResponse(_message.Message):
    __slots__ = ("success", "closed", "object_detected", "message", "unchanged")
    SUCCESS_FIELD_NUMBER: _ClassVar[int]
    CLOSED_FIELD_NUMBER: _ClassVar[int]
    OBJECT_DETECTED_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    UNCHANGED_FIELD_NUMBER: _ClassVar[int]
    success: bool
    closed: bool
    object_detected: bool
    message: str
    unchanged: bool
    def __init__(self, success: _Optional[bool] = ..., closed: _Optional[bool] = ..., object_detected: _Optional[bool] = ..., message: _Optional[str] = ..., unchanged: _Optional[bool] = ...) -> None: ...

class StopRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class EmergencyStopRequest(_message.Message):
    __slots__ = ("release",)
    RELEASE_FIELD_NUMBER: _ClassVar[int]
    release: bool
    def __init__(self, release: _Optional[bool] = ...) -> None: ...

class ClearErrorRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class EnableRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class DisableRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...
