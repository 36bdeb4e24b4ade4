"""The one validated settings model of pickplace: one module per section and the loader.

Sources, lowest priority first: ``config/default.yaml``, then the selected profile
``config/profiles/<profile>.yaml``, then an optional extra YAML file, then ``PICKPLACE_*``
environment variables (``loader``). Every public name is re-exported here, so callers write
``from services.common.settings import Settings, load_settings``.
"""

from services.common.settings.base import (
    LOOPBACK_HOSTS,
    CubeColor,
    Model,
    Vec2,
    Vec3,
    Vec6,
    endpoint_host,
    is_loopback,
)
from services.common.settings.database import DatabaseSettings
from services.common.settings.gateway import GatewaySettings
from services.common.settings.grasp import (
    CubeSortSettings,
    ForceClosureSettings,
    GraspGripperSettings,
    GraspSettings,
    RodStandSettings,
)
from services.common.settings.gripper import GripperSettings
from services.common.settings.loader import (
    CONFIG_DIR,
    CONFIG_FILE_ENV,
    PROFILE_ENV,
    REPO_ROOT,
    Settings,
    deep_merge,
    format_validation_error,
    load_settings,
    read_yaml,
)
from services.common.settings.motion import MotionSettings, ToolSettings
from services.common.settings.net import GrpcSettings, ZenohSettings
from services.common.settings.observability import LoggingSettings, MetricsSettings, StateSettings
from services.common.settings.record import FoxgloveSettings, McapCompression, RecordSettings
from services.common.settings.robot import (
    KeyPoseCycleSettings,
    ReconnectSettings,
    RobotSettings,
    WorkspaceBounds,
)
from services.common.settings.sim import (
    SimSettings,
    TwinCameraSettings,
    TwinPhysicsSettings,
    TwinSceneSettings,
    TwinSettings,
)
from services.common.settings.task import TaskSettings
from services.common.settings.vision import (
    CalibrationBoardSettings,
    CalibrationSettings,
    CameraSourceSettings,
    CubeDetectionSettings,
    ObstacleRuleSettings,
    RodDetectionSettings,
    TablePlaneSettings,
    VisionSettings,
)

__all__ = [
    "CONFIG_DIR",
    "CONFIG_FILE_ENV",
    "LOOPBACK_HOSTS",
    "PROFILE_ENV",
    "REPO_ROOT",
    "CalibrationBoardSettings",
    "CalibrationSettings",
    "CameraSourceSettings",
    "CubeColor",
    "CubeDetectionSettings",
    "CubeSortSettings",
    "DatabaseSettings",
    "ForceClosureSettings",
    "FoxgloveSettings",
    "GatewaySettings",
    "GraspGripperSettings",
    "GraspSettings",
    "GripperSettings",
    "GrpcSettings",
    "KeyPoseCycleSettings",
    "LoggingSettings",
    "McapCompression",
    "MetricsSettings",
    "Model",
    "MotionSettings",
    "ObstacleRuleSettings",
    "ReconnectSettings",
    "RecordSettings",
    "RobotSettings",
    "RodDetectionSettings",
    "RodStandSettings",
    "Settings",
    "SimSettings",
    "StateSettings",
    "TablePlaneSettings",
    "TaskSettings",
    "ToolSettings",
    "TwinCameraSettings",
    "TwinPhysicsSettings",
    "TwinSceneSettings",
    "TwinSettings",
    "Vec2",
    "Vec3",
    "Vec6",
    "VisionSettings",
    "WorkspaceBounds",
    "ZenohSettings",
    "deep_merge",
    "endpoint_host",
    "format_validation_error",
    "is_loopback",
    "load_settings",
    "read_yaml",
]
