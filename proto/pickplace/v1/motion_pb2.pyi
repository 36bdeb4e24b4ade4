from pickplace.v1 import common_pb2 as _common_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class CollisionBox(_message.Message):
    __slots__ = ("name", "x_min", "x_max", "y_min", "y_max", "z_min", "z_max")
    NAME_FIELD_NUMBER: _ClassVar[int]
    X_MIN_FIELD_NUMBER: _ClassVar[int]
    X_MAX_FIELD_NUMBER: _ClassVar[int]
    Y_MIN_FIELD_NUMBER: _ClassVar[int]
    Y_MAX_FIELD_NUMBER: _ClassVar[int]
    Z_MIN_FIELD_NUMBER: _ClassVar[int]
    Z_MAX_FIELD_NUMBER: _ClassVar[int]
    name: str
    x_min: float
    x_max: float
    y_min: float
    y_max: float
    z_min: float
    z_max: float
    def __init__(self, name: _Optional[str] = ..., x_min: _Optional[float] = ..., x_max: _Optional[float] = ..., y_min: _Optional[float] = ..., y_max: _Optional[float] = ..., z_min: _Optional[float] = ..., z_max: _Optional[float] = ...) -> None: ...

class AttachedObject(_message.Message):
    __slots__ = ("shape", "radius", "length", "size", "tool_to_object")
    class Shape(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        SHAPE_UNSPECIFIED: _ClassVar[AttachedObject.Shape]
        CYLINDER: _ClassVar[AttachedObject.Shape]
        BOX: _ClassVar[AttachedObject.Shape]
    SHAPE_UNSPECIFIED: AttachedObject.Shape
    CYLINDER: AttachedObject.Shape
    BOX: AttachedObject.Shape
    SHAPE_FIELD_NUMBER: _ClassVar[int]
    RADIUS_FIELD_NUMBER: _ClassVar[int]
    LENGTH_FIELD_NUMBER: _ClassVar[int]
    SIZE_FIELD_NUMBER: _ClassVar[int]
    TOOL_TO_OBJECT_FIELD_NUMBER: _ClassVar[int]
    shape: AttachedObject.Shape
    radius: float
    length: float
    size: _containers.RepeatedScalarFieldContainer[float]
    tool_to_object: _common_pb2.Pose
    def __init__(self, shape: _Optional[_Union[AttachedObject.Shape, str]] = ..., radius: _Optional[float] = ..., length: _Optional[float] = ..., size: _Optional[_Iterable[float]] = ..., tool_to_object: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ...) -> None: ...

class AllowedCollision(_message.Message):
    __slots__ = ("a", "b")
    A_FIELD_NUMBER: _ClassVar[int]
    B_FIELD_NUMBER: _ClassVar[int]
    a: str
    b: str
    def __init__(self, a: _Optional[str] = ..., b: _Optional[str] = ...) -> None: ...

class PlanningScene(_message.Message):
    __slots__ = ("boxes", "no_table", "table_z", "attached", "padding", "box_y_extension", "allowed")
    BOXES_FIELD_NUMBER: _ClassVar[int]
    NO_TABLE_FIELD_NUMBER: _ClassVar[int]
    TABLE_Z_FIELD_NUMBER: _ClassVar[int]
    ATTACHED_FIELD_NUMBER: _ClassVar[int]
    PADDING_FIELD_NUMBER: _ClassVar[int]
    BOX_Y_EXTENSION_FIELD_NUMBER: _ClassVar[int]
    ALLOWED_FIELD_NUMBER: _ClassVar[int]
    boxes: _containers.RepeatedCompositeFieldContainer[CollisionBox]
    no_table: bool
    table_z: float
    attached: AttachedObject
    padding: float
    box_y_extension: float
    allowed: _containers.RepeatedCompositeFieldContainer[AllowedCollision]
    def __init__(self, boxes: _Optional[_Iterable[_Union[CollisionBox, _Mapping]]] = ..., no_table: _Optional[bool] = ..., table_z: _Optional[float] = ..., attached: _Optional[_Union[AttachedObject, _Mapping]] = ..., padding: _Optional[float] = ..., box_y_extension: _Optional[float] = ..., allowed: _Optional[_Iterable[_Union[AllowedCollision, _Mapping]]] = ...) -> None: ...

class MotionOptions(_message.Message):
    __slots__ = ("robot_model", "planner", "planning_time_s", "velocity_scale", "acceleration_scale", "knot_period_s")
    ROBOT_MODEL_FIELD_NUMBER: _ClassVar[int]
    PLANNER_FIELD_NUMBER: _ClassVar[int]
    PLANNING_TIME_S_FIELD_NUMBER: _ClassVar[int]
    VELOCITY_SCALE_FIELD_NUMBER: _ClassVar[int]
    ACCELERATION_SCALE_FIELD_NUMBER: _ClassVar[int]
    KNOT_PERIOD_S_FIELD_NUMBER: _ClassVar[int]
    robot_model: str
    planner: str
    planning_time_s: float
    velocity_scale: float
    acceleration_scale: float
    knot_period_s: float
    def __init__(self, robot_model: _Optional[str] = ..., planner: _Optional[str] = ..., planning_time_s: _Optional[float] = ..., velocity_scale: _Optional[float] = ..., acceleration_scale: _Optional[float] = ..., knot_period_s: _Optional[float] = ...) -> None: ...

class SolveIKRequest(_message.Message):
    __slots__ = ("target", "seed", "method", "robot_model")
    TARGET_FIELD_NUMBER: _ClassVar[int]
    SEED_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    ROBOT_MODEL_FIELD_NUMBER: _ClassVar[int]
    target: _common_pb2.Pose
    seed: _containers.RepeatedScalarFieldContainer[float]
    method: str
    robot_model: str
    def __init__(self, target: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., seed: _Optional[_Iterable[float]] = ..., method: _Optional[str] = ..., robot_model: _Optional[str] = ...) -> None: ...

class IKSolution(_message.Message):
    __slots__ = ("positions", "manipulability")
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    MANIPULABILITY_FIELD_NUMBER: _ClassVar[int]
    positions: _containers.RepeatedScalarFieldContainer[float]
    manipulability: float
    def __init__(self, positions: _Optional[_Iterable[float]] = ..., manipulability: _Optional[float] = ...) -> None: ...

class SolveIKResponse(_message.Message):
    __slots__ = ("best", "solutions", "method", "position_error", "rotation_error")
    BEST_FIELD_NUMBER: _ClassVar[int]
    SOLUTIONS_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    POSITION_ERROR_FIELD_NUMBER: _ClassVar[int]
    ROTATION_ERROR_FIELD_NUMBER: _ClassVar[int]
    best: IKSolution
    solutions: _containers.RepeatedCompositeFieldContainer[IKSolution]
    method: str
    position_error: float
    rotation_error: float
    def __init__(self, best: _Optional[_Union[IKSolution, _Mapping]] = ..., solutions: _Optional[_Iterable[_Union[IKSolution, _Mapping]]] = ..., method: _Optional[str] = ..., position_error: _Optional[float] = ..., rotation_error: _Optional[float] = ...) -> None: ...

class PlanJointsRequest(_message.Message):
    __slots__ = ("start", "goal", "goal_pose", "shortest_angle", "scene", "options")
    START_FIELD_NUMBER: _ClassVar[int]
    GOAL_FIELD_NUMBER: _ClassVar[int]
    GOAL_POSE_FIELD_NUMBER: _ClassVar[int]
    SHORTEST_ANGLE_FIELD_NUMBER: _ClassVar[int]
    SCENE_FIELD_NUMBER: _ClassVar[int]
    OPTIONS_FIELD_NUMBER: _ClassVar[int]
    start: _containers.RepeatedScalarFieldContainer[float]
    goal: _containers.RepeatedScalarFieldContainer[float]
    goal_pose: _common_pb2.Pose
    shortest_angle: bool
    scene: PlanningScene
    options: MotionOptions
    def __init__(self, start: _Optional[_Iterable[float]] = ..., goal: _Optional[_Iterable[float]] = ..., goal_pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., shortest_angle: _Optional[bool] = ..., scene: _Optional[_Union[PlanningScene, _Mapping]] = ..., options: _Optional[_Union[MotionOptions, _Mapping]] = ...) -> None: ...

class PlanCartesianRequest(_message.Message):
    __slots__ = ("start", "poses", "scene", "options")
    START_FIELD_NUMBER: _ClassVar[int]
    POSES_FIELD_NUMBER: _ClassVar[int]
    SCENE_FIELD_NUMBER: _ClassVar[int]
    OPTIONS_FIELD_NUMBER: _ClassVar[int]
    start: _containers.RepeatedScalarFieldContainer[float]
    poses: _containers.RepeatedCompositeFieldContainer[_common_pb2.Pose]
    scene: PlanningScene
    options: MotionOptions
    def __init__(self, start: _Optional[_Iterable[float]] = ..., poses: _Optional[_Iterable[_Union[_common_pb2.Pose, _Mapping]]] = ..., scene: _Optional[_Union[PlanningScene, _Mapping]] = ..., options: _Optional[_Union[MotionOptions, _Mapping]] = ...) -> None: ...

class MotionWaypoint(_message.Message):
    __slots__ = ("motion", "pose", "joints", "label", "scene", "options", "blend", "blend_tolerance_m")
    class MotionType(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        MOTION_TYPE_UNSPECIFIED: _ClassVar[MotionWaypoint.MotionType]
        JOINT: _ClassVar[MotionWaypoint.MotionType]
        LINEAR: _ClassVar[MotionWaypoint.MotionType]
    MOTION_TYPE_UNSPECIFIED: MotionWaypoint.MotionType
    JOINT: MotionWaypoint.MotionType
    LINEAR: MotionWaypoint.MotionType
    MOTION_FIELD_NUMBER: _ClassVar[int]
    POSE_FIELD_NUMBER: _ClassVar[int]
    JOINTS_FIELD_NUMBER: _ClassVar[int]
    LABEL_FIELD_NUMBER: _ClassVar[int]
    SCENE_FIELD_NUMBER: _ClassVar[int]
    OPTIONS_FIELD_NUMBER: _ClassVar[int]
    BLEND_FIELD_NUMBER: _ClassVar[int]
    BLEND_TOLERANCE_M_FIELD_NUMBER: _ClassVar[int]
    motion: MotionWaypoint.MotionType
    pose: _common_pb2.Pose
    joints: _containers.RepeatedScalarFieldContainer[float]
    label: str
    scene: PlanningScene
    options: MotionOptions
    blend: bool
    blend_tolerance_m: float
    def __init__(self, motion: _Optional[_Union[MotionWaypoint.MotionType, str]] = ..., pose: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., joints: _Optional[_Iterable[float]] = ..., label: _Optional[str] = ..., scene: _Optional[_Union[PlanningScene, _Mapping]] = ..., options: _Optional[_Union[MotionOptions, _Mapping]] = ..., blend: _Optional[bool] = ..., blend_tolerance_m: _Optional[float] = ...) -> None: ...

class PlanWaypointsRequest(_message.Message):
    __slots__ = ("start", "waypoints", "scene", "options", "start_velocity")
    START_FIELD_NUMBER: _ClassVar[int]
    WAYPOINTS_FIELD_NUMBER: _ClassVar[int]
    SCENE_FIELD_NUMBER: _ClassVar[int]
    OPTIONS_FIELD_NUMBER: _ClassVar[int]
    START_VELOCITY_FIELD_NUMBER: _ClassVar[int]
    start: _containers.RepeatedScalarFieldContainer[float]
    waypoints: _containers.RepeatedCompositeFieldContainer[MotionWaypoint]
    scene: PlanningScene
    options: MotionOptions
    start_velocity: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, start: _Optional[_Iterable[float]] = ..., waypoints: _Optional[_Iterable[_Union[MotionWaypoint, _Mapping]]] = ..., scene: _Optional[_Union[PlanningScene, _Mapping]] = ..., options: _Optional[_Union[MotionOptions, _Mapping]] = ..., start_velocity: _Optional[_Iterable[float]] = ...) -> None: ...

class PlanResponse(_message.Message):
    __slots__ = ("trajectory", "planner", "planning_time_s", "timing_time_s", "duration_s", "path_points", "notes", "velocity_ratio", "acceleration_ratio", "jerk_ratio", "segments")
    TRAJECTORY_FIELD_NUMBER: _ClassVar[int]
    PLANNER_FIELD_NUMBER: _ClassVar[int]
    PLANNING_TIME_S_FIELD_NUMBER: _ClassVar[int]
    TIMING_TIME_S_FIELD_NUMBER: _ClassVar[int]
    DURATION_S_FIELD_NUMBER: _ClassVar[int]
    PATH_POINTS_FIELD_NUMBER: _ClassVar[int]
    NOTES_FIELD_NUMBER: _ClassVar[int]
    VELOCITY_RATIO_FIELD_NUMBER: _ClassVar[int]
    ACCELERATION_RATIO_FIELD_NUMBER: _ClassVar[int]
    JERK_RATIO_FIELD_NUMBER: _ClassVar[int]
    SEGMENTS_FIELD_NUMBER: _ClassVar[int]
    trajectory: _common_pb2.JointTrajectory
    planner: str
    planning_time_s: float
    timing_time_s: float
    duration_s: float
    path_points: int
    notes: _containers.RepeatedScalarFieldContainer[str]
    velocity_ratio: float
    acceleration_ratio: float
    jerk_ratio: float
    segments: _containers.RepeatedCompositeFieldContainer[_common_pb2.JointTrajectory]
    def __init__(self, trajectory: _Optional[_Union[_common_pb2.JointTrajectory, _Mapping]] = ..., planner: _Optional[str] = ..., planning_time_s: _Optional[float] = ..., timing_time_s: _Optional[float] = ..., duration_s: _Optional[float] = ..., path_points: _Optional[int] = ..., notes: _Optional[_Iterable[str]] = ..., velocity_ratio: _Optional[float] = ..., acceleration_ratio: _Optional[float] = ..., jerk_ratio: _Optional[float] = ..., segments: _Optional[_Iterable[_Union[_common_pb2.JointTrajectory, _Mapping]]] = ...) -> None: ...

class CheckTrajectoryRequest(_message.Message):
    __slots__ = ("trajectory", "scene", "options", "skip_collisions")
    TRAJECTORY_FIELD_NUMBER: _ClassVar[int]
    SCENE_FIELD_NUMBER: _ClassVar[int]
    OPTIONS_FIELD_NUMBER: _ClassVar[int]
    SKIP_COLLISIONS_FIELD_NUMBER: _ClassVar[int]
    trajectory: _common_pb2.JointTrajectory
    scene: PlanningScene
    options: MotionOptions
    skip_collisions: bool
    def __init__(self, trajectory: _Optional[_Union[_common_pb2.JointTrajectory, _Mapping]] = ..., scene: _Optional[_Union[PlanningScene, _Mapping]] = ..., options: _Optional[_Union[MotionOptions, _Mapping]] = ..., skip_collisions: _Optional[bool] = ...) -> None: ...

class CheckTrajectoryResponse(_message.Message):
    __slots__ = ("ok", "message", "velocity_ratio", "acceleration_ratio", "jerk_ratio", "collision_time_s")
    OK_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    VELOCITY_RATIO_FIELD_NUMBER: _ClassVar[int]
    ACCELERATION_RATIO_FIELD_NUMBER: _ClassVar[int]
    JERK_RATIO_FIELD_NUMBER: _ClassVar[int]
    COLLISION_TIME_S_FIELD_NUMBER: _ClassVar[int]
    ok: bool
    message: str
    velocity_ratio: float
    acceleration_ratio: float
    jerk_ratio: float
    collision_time_s: float
    def __init__(self, ok: _Optional[bool] = ..., message: _Optional[str] = ..., velocity_ratio: _Optional[float] = ..., acceleration_ratio: _Optional[float] = ..., jerk_ratio: _Optional[float] = ..., collision_time_s: _Optional[float] = ...) -> None: ...
