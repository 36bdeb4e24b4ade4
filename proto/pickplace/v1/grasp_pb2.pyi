from pickplace.v1 import common_pb2 as _common_pb2
from pickplace.v1 import motion_pb2 as _motion_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class ComputeGraspsRequest(_message.Message):
    __slots__ = ("object_pose", "object_shape", "object_width", "object_depth", "object_height", "num_candidates", "current_joints", "obstacles", "skip_reachability")
    OBJECT_POSE_FIELD_NUMBER: _ClassVar[int]
    OBJECT_SHAPE_FIELD_NUMBER: _ClassVar[int]
    OBJECT_WIDTH_FIELD_NUMBER: _ClassVar[int]
    OBJECT_DEPTH_FIELD_NUMBER: _ClassVar[int]
    OBJECT_HEIGHT_FIELD_NUMBER: _ClassVar[int]
    NUM_CANDIDATES_FIELD_NUMBER: _ClassVar[int]
    CURRENT_JOINTS_FIELD_NUMBER: _ClassVar[int]
    OBSTACLES_FIELD_NUMBER: _ClassVar[int]
    SKIP_REACHABILITY_FIELD_NUMBER: _ClassVar[int]
    object_pose: _common_pb2.Pose
    object_shape: str
    object_width: float
    object_depth: float
    object_height: float
    num_candidates: int
    current_joints: _containers.RepeatedScalarFieldContainer[float]
    obstacles: _containers.RepeatedCompositeFieldContainer[_motion_pb2.CollisionBox]
    skip_reachability: bool
    def __init__(self, object_pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., object_shape: _Optional[str] = ..., object_width: _Optional[float] = ..., object_depth: _Optional[float] = ..., object_height: _Optional[float] = ..., num_candidates: _Optional[int] = ..., current_joints: _Optional[_Iterable[float]] = ..., obstacles: _Optional[_Iterable[_Union[_motion_pb2.CollisionBox, _Mapping]]] = ..., skip_reachability: _Optional[bool] = ...) -> None: ...

class GraspCandidate(_message.Message):
    __slots__ = ("pose", "quality", "width_quality", "epsilon", "force_closure", "approach_distance", "approach_direction", "gripper_width", "opening", "force", "joints", "label")
    POSE_FIELD_NUMBER: _ClassVar[int]
    QUALITY_FIELD_NUMBER: _ClassVar[int]
    WIDTH_QUALITY_FIELD_NUMBER: _ClassVar[int]
    EPSILON_FIELD_NUMBER: _ClassVar[int]
    FORCE_CLOSURE_FIELD_NUMBER: _ClassVar[int]
    APPROACH_DISTANCE_FIELD_NUMBER: _ClassVar[int]
    APPROACH_DIRECTION_FIELD_NUMBER: _ClassVar[int]
    GRIPPER_WIDTH_FIELD_NUMBER: _ClassVar[int]
    OPENING_FIELD_NUMBER: _ClassVar[int]
    FORCE_FIELD_NUMBER: _ClassVar[int]
    JOINTS_FIELD_NUMBER: _ClassVar[int]
    LABEL_FIELD_NUMBER: _ClassVar[int]
    pose: _common_pb2.Pose
    quality: float
    width_quality: float
    epsilon: float
    force_closure: bool
    approach_distance: float
    approach_direction: _containers.RepeatedScalarFieldContainer[float]
    gripper_width: float
    opening: float
    force: float
    joints: _containers.RepeatedScalarFieldContainer[float]
    label: str
    def __init__(self, pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., quality: _Optional[float] = ..., width_quality: _Optional[float] = ..., epsilon: _Optional[float] = ..., force_closure: _Optional[bool] = ..., approach_distance: _Optional[float] = ..., approach_direction: _Optional[_Iterable[float]] = ..., gripper_width: _Optional[float] = ..., opening: _Optional[float] = ..., force: _Optional[float] = ..., joints: _Optional[_Iterable[float]] = ..., label: _Optional[str] = ...) -> None: ...

class ComputeGraspsResponse(_message.Message):
    __slots__ = ("grasps", "success", "message", "candidates_generated", "rejected")
    class RejectedEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    GRASPS_FIELD_NUMBER: _ClassVar[int]
    SUCCESS_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    CANDIDATES_GENERATED_FIELD_NUMBER: _ClassVar[int]
    REJECTED_FIELD_NUMBER: _ClassVar[int]
    grasps: _containers.RepeatedCompositeFieldContainer[GraspCandidate]
    success: bool
    message: str
    candidates_generated: int
    rejected: _containers.ScalarMap[str, int]
    def __init__(self, grasps: _Optional[_Iterable[_Union[GraspCandidate, _Mapping]]] = ..., success: _Optional[bool] = ..., message: _Optional[str] = ..., candidates_generated: _Optional[int] = ..., rejected: _Optional[_Mapping[str, int]] = ...) -> None: ...

class Guard(_message.Message):
    __slots__ = ("force_drop_n", "overtravel_m", "speed_m_s", "direction", "slow_band_m", "approach_speed_m_s")
    FORCE_DROP_N_FIELD_NUMBER: _ClassVar[int]
    OVERTRAVEL_M_FIELD_NUMBER: _ClassVar[int]
    SPEED_M_S_FIELD_NUMBER: _ClassVar[int]
    DIRECTION_FIELD_NUMBER: _ClassVar[int]
    SLOW_BAND_M_FIELD_NUMBER: _ClassVar[int]
    APPROACH_SPEED_M_S_FIELD_NUMBER: _ClassVar[int]
    force_drop_n: float
    overtravel_m: float
    speed_m_s: float
    direction: _containers.RepeatedScalarFieldContainer[float]
    slow_band_m: float
    approach_speed_m_s: float
    def __init__(self, force_drop_n: _Optional[float] = ..., overtravel_m: _Optional[float] = ..., speed_m_s: _Optional[float] = ..., direction: _Optional[_Iterable[float]] = ..., slow_band_m: _Optional[float] = ..., approach_speed_m_s: _Optional[float] = ...) -> None: ...

class PickWaypoint(_message.Message):
    __slots__ = ("name", "motion", "pose", "joints", "gripper", "guard", "holding")
    class Motion(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        MOTION_UNSPECIFIED: _ClassVar[PickWaypoint.Motion]
        JOINT: _ClassVar[PickWaypoint.Motion]
        LINEAR: _ClassVar[PickWaypoint.Motion]
        HOLD: _ClassVar[PickWaypoint.Motion]
    MOTION_UNSPECIFIED: PickWaypoint.Motion
    JOINT: PickWaypoint.Motion
    LINEAR: PickWaypoint.Motion
    HOLD: PickWaypoint.Motion
    class Gripper(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        GRIPPER_NONE: _ClassVar[PickWaypoint.Gripper]
        OPEN: _ClassVar[PickWaypoint.Gripper]
        CLOSE: _ClassVar[PickWaypoint.Gripper]
    GRIPPER_NONE: PickWaypoint.Gripper
    OPEN: PickWaypoint.Gripper
    CLOSE: PickWaypoint.Gripper
    NAME_FIELD_NUMBER: _ClassVar[int]
    MOTION_FIELD_NUMBER: _ClassVar[int]
    POSE_FIELD_NUMBER: _ClassVar[int]
    JOINTS_FIELD_NUMBER: _ClassVar[int]
    GRIPPER_FIELD_NUMBER: _ClassVar[int]
    GUARD_FIELD_NUMBER: _ClassVar[int]
    HOLDING_FIELD_NUMBER: _ClassVar[int]
    name: str
    motion: PickWaypoint.Motion
    pose: _common_pb2.Pose
    joints: _containers.RepeatedScalarFieldContainer[float]
    gripper: PickWaypoint.Gripper
    guard: Guard
    holding: bool
    def __init__(self, name: _Optional[str] = ..., motion: _Optional[_Union[PickWaypoint.Motion, str]] = ..., pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., joints: _Optional[_Iterable[float]] = ..., gripper: _Optional[_Union[PickWaypoint.Gripper, str]] = ..., guard: _Optional[_Union[Guard, _Mapping]] = ..., holding: _Optional[bool] = ...) -> None: ...

class PickPlan(_message.Message):
    __slots__ = ("header", "task", "waypoints", "grasp", "held_object", "place_position", "metrics", "summary", "planning_time_s")
    class MetricsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    HEADER_FIELD_NUMBER: _ClassVar[int]
    TASK_FIELD_NUMBER: _ClassVar[int]
    WAYPOINTS_FIELD_NUMBER: _ClassVar[int]
    GRASP_FIELD_NUMBER: _ClassVar[int]
    HELD_OBJECT_FIELD_NUMBER: _ClassVar[int]
    PLACE_POSITION_FIELD_NUMBER: _ClassVar[int]
    METRICS_FIELD_NUMBER: _ClassVar[int]
    SUMMARY_FIELD_NUMBER: _ClassVar[int]
    PLANNING_TIME_S_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    task: str
    waypoints: _containers.RepeatedCompositeFieldContainer[PickWaypoint]
    grasp: GraspCandidate
    held_object: _motion_pb2.AttachedObject
    place_position: _containers.RepeatedScalarFieldContainer[float]
    metrics: _containers.ScalarMap[str, float]
    summary: str
    planning_time_s: float
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., task: _Optional[str] = ..., waypoints: _Optional[_Iterable[_Union[PickWaypoint, _Mapping]]] = ..., grasp: _Optional[_Union[GraspCandidate, _Mapping]] = ..., held_object: _Optional[_Union[_motion_pb2.AttachedObject, _Mapping]] = ..., place_position: _Optional[_Iterable[float]] = ..., metrics: _Optional[_Mapping[str, float]] = ..., summary: _Optional[str] = ..., planning_time_s: _Optional[float] = ...) -> None: ...

class PickAndStandRequest(_message.Message):
    __slots__ = ("center", "axis", "length", "diameter", "current_joints", "place_xy", "obstacles", "alternative", "grasp_offset", "other_ik_branches")
    CENTER_FIELD_NUMBER: _ClassVar[int]
    AXIS_FIELD_NUMBER: _ClassVar[int]
    LENGTH_FIELD_NUMBER: _ClassVar[int]
    DIAMETER_FIELD_NUMBER: _ClassVar[int]
    CURRENT_JOINTS_FIELD_NUMBER: _ClassVar[int]
    PLACE_XY_FIELD_NUMBER: _ClassVar[int]
    OBSTACLES_FIELD_NUMBER: _ClassVar[int]
    ALTERNATIVE_FIELD_NUMBER: _ClassVar[int]
    GRASP_OFFSET_FIELD_NUMBER: _ClassVar[int]
    OTHER_IK_BRANCHES_FIELD_NUMBER: _ClassVar[int]
    center: _containers.RepeatedScalarFieldContainer[float]
    axis: _containers.RepeatedScalarFieldContainer[float]
    length: float
    diameter: float
    current_joints: _containers.RepeatedScalarFieldContainer[float]
    place_xy: _containers.RepeatedScalarFieldContainer[float]
    obstacles: _containers.RepeatedCompositeFieldContainer[_motion_pb2.CollisionBox]
    alternative: int
    grasp_offset: float
    other_ik_branches: bool
    def __init__(self, center: _Optional[_Iterable[float]] = ..., axis: _Optional[_Iterable[float]] = ..., length: _Optional[float] = ..., diameter: _Optional[float] = ..., current_joints: _Optional[_Iterable[float]] = ..., place_xy: _Optional[_Iterable[float]] = ..., obstacles: _Optional[_Iterable[_Union[_motion_pb2.CollisionBox, _Mapping]]] = ..., alternative: _Optional[int] = ..., grasp_offset: _Optional[float] = ..., other_ik_branches: _Optional[bool] = ...) -> None: ...

class PickAndPlaceRequest(_message.Message):
    __slots__ = ("cube_pose", "size", "color", "current_joints", "obstacles", "alternative")
    CUBE_POSE_FIELD_NUMBER: _ClassVar[int]
    SIZE_FIELD_NUMBER: _ClassVar[int]
    COLOR_FIELD_NUMBER: _ClassVar[int]
    CURRENT_JOINTS_FIELD_NUMBER: _ClassVar[int]
    OBSTACLES_FIELD_NUMBER: _ClassVar[int]
    ALTERNATIVE_FIELD_NUMBER: _ClassVar[int]
    cube_pose: _common_pb2.Pose
    size: float
    color: str
    current_joints: _containers.RepeatedScalarFieldContainer[float]
    obstacles: _containers.RepeatedCompositeFieldContainer[_motion_pb2.CollisionBox]
    alternative: int
    def __init__(self, cube_pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., size: _Optional[float] = ..., color: _Optional[str] = ..., current_joints: _Optional[_Iterable[float]] = ..., obstacles: _Optional[_Iterable[_Union[_motion_pb2.CollisionBox, _Mapping]]] = ..., alternative: _Optional[int] = ...) -> None: ...
