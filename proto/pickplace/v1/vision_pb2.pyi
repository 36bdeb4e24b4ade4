from pickplace.v1 import common_pb2 as _common_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Visibility(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    VISIBILITY_UNSPECIFIED: _ClassVar[Visibility]
    VISIBILITY_WHOLE: _ClassVar[Visibility]
    VISIBILITY_CUT_BY_EDGE: _ClassVar[Visibility]
    VISIBILITY_OCCLUDED: _ClassVar[Visibility]
VISIBILITY_UNSPECIFIED: Visibility
VISIBILITY_WHOLE: Visibility
VISIBILITY_CUT_BY_EDGE: Visibility
VISIBILITY_OCCLUDED: Visibility

class Vec3(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class CameraIntrinsics(_message.Message):
    __slots__ = ("width", "height", "fx", "fy", "cx", "cy", "distortion")
    WIDTH_FIELD_NUMBER: _ClassVar[int]
    HEIGHT_FIELD_NUMBER: _ClassVar[int]
    FX_FIELD_NUMBER: _ClassVar[int]
    FY_FIELD_NUMBER: _ClassVar[int]
    CX_FIELD_NUMBER: _ClassVar[int]
    CY_FIELD_NUMBER: _ClassVar[int]
    DISTORTION_FIELD_NUMBER: _ClassVar[int]
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, width: _Optional[int] = ..., height: _Optional[int] = ..., fx: _Optional[float] = ..., fy: _Optional[float] = ..., cx: _Optional[float] = ..., cy: _Optional[float] = ..., distortion: _Optional[_Iterable[float]] = ...) -> None: ...

class RGBDFrame(_message.Message):
    __slots__ = ("header", "intrinsics", "color_rgb8", "depth_u16", "depth_scale")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    INTRINSICS_FIELD_NUMBER: _ClassVar[int]
    COLOR_RGB8_FIELD_NUMBER: _ClassVar[int]
    DEPTH_U16_FIELD_NUMBER: _ClassVar[int]
    DEPTH_SCALE_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    intrinsics: CameraIntrinsics
    color_rgb8: bytes
    depth_u16: bytes
    depth_scale: float
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., intrinsics: _Optional[_Union[CameraIntrinsics, _Mapping]] = ..., color_rgb8: _Optional[bytes] = ..., depth_u16: _Optional[bytes] = ..., depth_scale: _Optional[float] = ...) -> None: ...

class Rgb(_message.Message):
    __slots__ = ("r", "g", "b")
    R_FIELD_NUMBER: _ClassVar[int]
    G_FIELD_NUMBER: _ClassVar[int]
    B_FIELD_NUMBER: _ClassVar[int]
    r: float
    g: float
    b: float
    def __init__(self, r: _Optional[float] = ..., g: _Optional[float] = ..., b: _Optional[float] = ...) -> None: ...

class RodDetection(_message.Message):
    __slots__ = ("center_camera", "axis_camera", "pose_camera", "has_base", "center_base", "axis_base", "pose_base", "length_m", "diameter_m", "confidence", "method", "n_depth_points")
    CENTER_CAMERA_FIELD_NUMBER: _ClassVar[int]
    AXIS_CAMERA_FIELD_NUMBER: _ClassVar[int]
    POSE_CAMERA_FIELD_NUMBER: _ClassVar[int]
    HAS_BASE_FIELD_NUMBER: _ClassVar[int]
    CENTER_BASE_FIELD_NUMBER: _ClassVar[int]
    AXIS_BASE_FIELD_NUMBER: _ClassVar[int]
    POSE_BASE_FIELD_NUMBER: _ClassVar[int]
    LENGTH_M_FIELD_NUMBER: _ClassVar[int]
    DIAMETER_M_FIELD_NUMBER: _ClassVar[int]
    CONFIDENCE_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    N_DEPTH_POINTS_FIELD_NUMBER: _ClassVar[int]
    center_camera: Vec3
    axis_camera: Vec3
    pose_camera: _common_pb2.Pose
    has_base: bool
    center_base: Vec3
    axis_base: Vec3
    pose_base: _common_pb2.Pose
    length_m: float
    diameter_m: float
    confidence: float
    method: str
    n_depth_points: int
    def __init__(self, center_camera: _Optional[_Union[Vec3, _Mapping]] = ..., axis_camera: _Optional[_Union[Vec3, _Mapping]] = ..., pose_camera: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., has_base: _Optional[bool] = ..., center_base: _Optional[_Union[Vec3, _Mapping]] = ..., axis_base: _Optional[_Union[Vec3, _Mapping]] = ..., pose_base: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., length_m: _Optional[float] = ..., diameter_m: _Optional[float] = ..., confidence: _Optional[float] = ..., method: _Optional[str] = ..., n_depth_points: _Optional[int] = ...) -> None: ...

class CubeDetection(_message.Message):
    __slots__ = ("centroid_camera", "pose_camera", "has_base", "centroid_base", "pose_base", "color_label", "n_points", "visibility", "mean_rgb", "fit_rms_m", "hidden_fraction")
    CENTROID_CAMERA_FIELD_NUMBER: _ClassVar[int]
    POSE_CAMERA_FIELD_NUMBER: _ClassVar[int]
    HAS_BASE_FIELD_NUMBER: _ClassVar[int]
    CENTROID_BASE_FIELD_NUMBER: _ClassVar[int]
    POSE_BASE_FIELD_NUMBER: _ClassVar[int]
    COLOR_LABEL_FIELD_NUMBER: _ClassVar[int]
    N_POINTS_FIELD_NUMBER: _ClassVar[int]
    VISIBILITY_FIELD_NUMBER: _ClassVar[int]
    MEAN_RGB_FIELD_NUMBER: _ClassVar[int]
    FIT_RMS_M_FIELD_NUMBER: _ClassVar[int]
    HIDDEN_FRACTION_FIELD_NUMBER: _ClassVar[int]
    centroid_camera: Vec3
    pose_camera: _common_pb2.Pose
    has_base: bool
    centroid_base: Vec3
    pose_base: _common_pb2.Pose
    color_label: str
    n_points: int
    visibility: Visibility
    mean_rgb: Rgb
    fit_rms_m: float
    hidden_fraction: float
    def __init__(self, centroid_camera: _Optional[_Union[Vec3, _Mapping]] = ..., pose_camera: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., has_base: _Optional[bool] = ..., centroid_base: _Optional[_Union[Vec3, _Mapping]] = ..., pose_base: _Optional[_Union[_common_pb2.Pose, _Mapping]] = ..., color_label: _Optional[str] = ..., n_points: _Optional[int] = ..., visibility: _Optional[_Union[Visibility, str]] = ..., mean_rgb: _Optional[_Union[Rgb, _Mapping]] = ..., fit_rms_m: _Optional[float] = ..., hidden_fraction: _Optional[float] = ...) -> None: ...

class BoxBounds(_message.Message):
    __slots__ = ("min", "max")
    MIN_FIELD_NUMBER: _ClassVar[int]
    MAX_FIELD_NUMBER: _ClassVar[int]
    min: Vec3
    max: Vec3
    def __init__(self, min: _Optional[_Union[Vec3, _Mapping]] = ..., max: _Optional[_Union[Vec3, _Mapping]] = ...) -> None: ...

class ObstacleBox(_message.Message):
    __slots__ = ("camera", "has_base", "base", "color_label", "n_points", "visibility", "mean_rgb", "recognised")
    CAMERA_FIELD_NUMBER: _ClassVar[int]
    HAS_BASE_FIELD_NUMBER: _ClassVar[int]
    BASE_FIELD_NUMBER: _ClassVar[int]
    COLOR_LABEL_FIELD_NUMBER: _ClassVar[int]
    N_POINTS_FIELD_NUMBER: _ClassVar[int]
    VISIBILITY_FIELD_NUMBER: _ClassVar[int]
    MEAN_RGB_FIELD_NUMBER: _ClassVar[int]
    RECOGNISED_FIELD_NUMBER: _ClassVar[int]
    camera: BoxBounds
    has_base: bool
    base: BoxBounds
    color_label: str
    n_points: int
    visibility: Visibility
    mean_rgb: Rgb
    recognised: bool
    def __init__(self, camera: _Optional[_Union[BoxBounds, _Mapping]] = ..., has_base: _Optional[bool] = ..., base: _Optional[_Union[BoxBounds, _Mapping]] = ..., color_label: _Optional[str] = ..., n_points: _Optional[int] = ..., visibility: _Optional[_Union[Visibility, str]] = ..., mean_rgb: _Optional[_Union[Rgb, _Mapping]] = ..., recognised: _Optional[bool] = ...) -> None: ...

class DetectedObjects(_message.Message):
    __slots__ = ("header", "rods", "cubes", "obstacles", "timings_ms", "notes", "rod_detected", "calibrated")
    class TimingsMsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    HEADER_FIELD_NUMBER: _ClassVar[int]
    RODS_FIELD_NUMBER: _ClassVar[int]
    CUBES_FIELD_NUMBER: _ClassVar[int]
    OBSTACLES_FIELD_NUMBER: _ClassVar[int]
    TIMINGS_MS_FIELD_NUMBER: _ClassVar[int]
    NOTES_FIELD_NUMBER: _ClassVar[int]
    ROD_DETECTED_FIELD_NUMBER: _ClassVar[int]
    CALIBRATED_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    rods: _containers.RepeatedCompositeFieldContainer[RodDetection]
    cubes: _containers.RepeatedCompositeFieldContainer[CubeDetection]
    obstacles: _containers.RepeatedCompositeFieldContainer[ObstacleBox]
    timings_ms: _containers.ScalarMap[str, float]
    notes: _containers.RepeatedScalarFieldContainer[str]
    rod_detected: bool
    calibrated: bool
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., rods: _Optional[_Iterable[_Union[RodDetection, _Mapping]]] = ..., cubes: _Optional[_Iterable[_Union[CubeDetection, _Mapping]]] = ..., obstacles: _Optional[_Iterable[_Union[ObstacleBox, _Mapping]]] = ..., timings_ms: _Optional[_Mapping[str, float]] = ..., notes: _Optional[_Iterable[str]] = ..., rod_detected: _Optional[bool] = ..., calibrated: _Optional[bool] = ...) -> None: ...

class DetectRequest(_message.Message):
    __slots__ = ("frame", "include_debug_image")
    FRAME_FIELD_NUMBER: _ClassVar[int]
    INCLUDE_DEBUG_IMAGE_FIELD_NUMBER: _ClassVar[int]
    frame: RGBDFrame
    include_debug_image: bool
    def __init__(self, frame: _Optional[_Union[RGBDFrame, _Mapping]] = ..., include_debug_image: _Optional[bool] = ...) -> None: ...

class DetectResponse(_message.Message):
    __slots__ = ("objects", "debug_jpeg")
    OBJECTS_FIELD_NUMBER: _ClassVar[int]
    DEBUG_JPEG_FIELD_NUMBER: _ClassVar[int]
    objects: DetectedObjects
    debug_jpeg: bytes
    def __init__(self, objects: _Optional[_Union[DetectedObjects, _Mapping]] = ..., debug_jpeg: _Optional[bytes] = ...) -> None: ...

class DebugImageRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class DebugImage(_message.Message):
    __slots__ = ("header", "jpeg")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    JPEG_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    jpeg: bytes
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., jpeg: _Optional[bytes] = ...) -> None: ...

class MeasureHeldRodRequest(_message.Message):
    __slots__ = ("point_base", "direction_base", "search_radius_m", "along_min_m", "along_max_m", "skip_min_m", "skip_max_m", "rod_diameter_m")
    POINT_BASE_FIELD_NUMBER: _ClassVar[int]
    DIRECTION_BASE_FIELD_NUMBER: _ClassVar[int]
    SEARCH_RADIUS_M_FIELD_NUMBER: _ClassVar[int]
    ALONG_MIN_M_FIELD_NUMBER: _ClassVar[int]
    ALONG_MAX_M_FIELD_NUMBER: _ClassVar[int]
    SKIP_MIN_M_FIELD_NUMBER: _ClassVar[int]
    SKIP_MAX_M_FIELD_NUMBER: _ClassVar[int]
    ROD_DIAMETER_M_FIELD_NUMBER: _ClassVar[int]
    point_base: Vec3
    direction_base: Vec3
    search_radius_m: float
    along_min_m: float
    along_max_m: float
    skip_min_m: float
    skip_max_m: float
    rod_diameter_m: float
    def __init__(self, point_base: _Optional[_Union[Vec3, _Mapping]] = ..., direction_base: _Optional[_Union[Vec3, _Mapping]] = ..., search_radius_m: _Optional[float] = ..., along_min_m: _Optional[float] = ..., along_max_m: _Optional[float] = ..., skip_min_m: _Optional[float] = ..., skip_max_m: _Optional[float] = ..., rod_diameter_m: _Optional[float] = ...) -> None: ...

class MeasureHeldRodResponse(_message.Message):
    __slots__ = ("header", "direction_base", "point_base", "n_points", "span_m", "rms_m", "tilt_deg")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    DIRECTION_BASE_FIELD_NUMBER: _ClassVar[int]
    POINT_BASE_FIELD_NUMBER: _ClassVar[int]
    N_POINTS_FIELD_NUMBER: _ClassVar[int]
    SPAN_M_FIELD_NUMBER: _ClassVar[int]
    RMS_M_FIELD_NUMBER: _ClassVar[int]
    TILT_DEG_FIELD_NUMBER: _ClassVar[int]
    header: _common_pb2.Header
    direction_base: Vec3
    point_base: Vec3
    n_points: int
    span_m: float
    rms_m: float
    tilt_deg: float
    def __init__(self, header: _Optional[_Union[_common_pb2.Header, _Mapping]] = ..., direction_base: _Optional[_Union[Vec3, _Mapping]] = ..., point_base: _Optional[_Union[Vec3, _Mapping]] = ..., n_points: _Optional[int] = ..., span_m: _Optional[float] = ..., rms_m: _Optional[float] = ..., tilt_deg: _Optional[float] = ...) -> None: ...
