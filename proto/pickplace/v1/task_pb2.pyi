from pickplace.v1 import common_pb2 as _common_pb2
from pickplace.v1 import motion_pb2 as _motion_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class PickStatus(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    PICK_STATUS_UNSPECIFIED: _ClassVar[PickStatus]
    PICK_STATUS_RUNNING: _ClassVar[PickStatus]
    PICK_STATUS_SUCCEEDED: _ClassVar[PickStatus]
    PICK_STATUS_FAILED: _ClassVar[PickStatus]
    PICK_STATUS_INTERRUPTED: _ClassVar[PickStatus]
PICK_STATUS_UNSPECIFIED: PickStatus
PICK_STATUS_RUNNING: PickStatus
PICK_STATUS_SUCCEEDED: PickStatus
PICK_STATUS_FAILED: PickStatus
PICK_STATUS_INTERRUPTED: PickStatus

class TaskStatus(_message.Message):
    __slots__ = ("header", "state", "message", "progress", "picks_completed", "picks_failed", "average_cycle_time", "task", "running", "cycle_index", "last_error", "cycle_active")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    STATE_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    PROGRESS_FIELD_NUMBER: _ClassVar[int]
    PICKS_COMPLETED_FIELD_NUMBER: _ClassVar[int]
    PICKS_FAILED_FIELD_NUMBER: _ClassVar[int]
    AVERAGE_CYCLE_TIME_FIELD_NUMBER: _ClassVar[int]
    TASK_FIELD_NUMBER: _ClassVar[int]
    RUNNING_FIELD_NUMBER: _ClassVar[int]
    CYCLE_INDEX_FIELD_NUMBER: _ClassVar[int]
    LAST_ERROR_FIELD_NUMBER: _ClassVar[int]
    CYCLE_ACTIVE_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    state: str
    message: str
    progress: float
    picks_completed: int
    picks_failed: int
    average_cycle_time: float
    task: str
    running: bool
    cycle_index: int
    last_error: str
    cycle_active: bool
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., state: _Optional[str] = ..., message: _Optional[str] = ..., progress: _Optional[float] = ..., picks_completed: _Optional[int] = ..., picks_failed: _Optional[int] = ..., average_cycle_time: _Optional[float] = ..., task: _Optional[str] = ..., running: _Optional[bool] = ..., cycle_index: _Optional[int] = ..., last_error: _Optional[str] = ..., cycle_active: _Optional[bool] = ...) -> None: ...

class PickEvent(_message.Message):
    __slots__ = ("header", "pick_id", "robot_id", "object_id", "object_class", "pick_pose", "place_pose", "grasp_quality", "cycle_time_s", "success", "stage_reached", "failure_reason", "error_code", "stage_durations_s", "attempts", "task", "status")
    class StageDurationsSEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    HEADER_FIELD_NUMBER: _ClassVar[int]
    PICK_ID_FIELD_NUMBER: _ClassVar[int]
    ROBOT_ID_FIELD_NUMBER: _ClassVar[int]
    OBJECT_ID_FIELD_NUMBER: _ClassVar[int]
    OBJECT_CLASS_FIELD_NUMBER: _ClassVar[int]
    PICK_POSE_FIELD_NUMBER: _ClassVar[int]
    PLACE_POSE_FIELD_NUMBER: _ClassVar[int]
    GRASP_QUALITY_FIELD_NUMBER: _ClassVar[int]
    CYCLE_TIME_S_FIELD_NUMBER: _ClassVar[int]
    SUCCESS_FIELD_NUMBER: _ClassVar[int]
    STAGE_REACHED_FIELD_NUMBER: _ClassVar[int]
    FAILURE_REASON_FIELD_NUMBER: _ClassVar[int]
    ERROR_CODE_FIELD_NUMBER: _ClassVar[int]
    STAGE_DURATIONS_S_FIELD_NUMBER: _ClassVar[int]
    ATTEMPTS_FIELD_NUMBER: _ClassVar[int]
    TASK_FIELD_NUMBER: _ClassVar[int]
    STATUS_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    pick_id: str
    robot_id: str
    object_id: str
    object_class: str
    pick_pose: _common_pb2.Pose
    place_pose: _common_pb2.Pose
    grasp_quality: float
    cycle_time_s: float
    success: bool
    stage_reached: str
    failure_reason: str
    error_code: str
    stage_durations_s: _containers.ScalarMap[str, float]
    attempts: int
    task: str
    status: PickStatus
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., pick_id: _Optional[str] = ..., robot_id: _Optional[str] = ..., object_id: _Optional[str] = ..., object_class: _Optional[str] = ..., pick_pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., place_pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., grasp_quality: _Optional[float] = ..., cycle_time_s: _Optional[float] = ..., success: _Optional[bool] = ..., stage_reached: _Optional[str] = ..., failure_reason: _Optional[str] = ..., error_code: _Optional[str] = ..., stage_durations_s: _Optional[_Mapping[str, float]] = ..., attempts: _Optional[int] = ..., task: _Optional[str] = ..., status: _Optional[_Union[PickStatus, str]] = ...) -> None: ...

class StartTaskRequest(_message.Message):
    __slots__ = ("task", "cycles")
    TASK_FIELD_NUMBER: _ClassVar[int]
    CYCLES_FIELD_NUMBER: _ClassVar[int]
    task: str
    cycles: int
    def __init__(self, task: _Optional[str] = ..., cycles: _Optional[int] = ...) -> None: ...

class StopTaskRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class TaskEmergencyStopRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class SingleCycleRequest(_message.Message):
    __slots__ = ("task",)
    TASK_FIELD_NUMBER: _ClassVar[int]
    task: str
    def __init__(self, task: _Optional[str] = ...) -> None: ...

class GetTaskStatusRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class TaskPlan(_message.Message):
    __slots__ = ("header", "cycle_index", "label", "tool_path", "boxes")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    CYCLE_INDEX_FIELD_NUMBER: _ClassVar[int]
    LABEL_FIELD_NUMBER: _ClassVar[int]
    TOOL_PATH_FIELD_NUMBER: _ClassVar[int]
    BOXES_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    cycle_index: int
    label: str
    tool_path: _containers.RepeatedCompositeFieldContainer[_common_pb2.Point]
    boxes: _containers.RepeatedCompositeFieldContainer[_motion_pb2.CollisionBox]
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., cycle_index: _Optional[int] = ..., label: _Optional[str] = ..., tool_path: _Optional[_Iterable[_Union[_common_pb2.Point, _Mapping]]] = ..., boxes: _Optional[_Iterable[_Union[_motion_pb2.CollisionBox, _Mapping]]] = ...) -> None: ...
