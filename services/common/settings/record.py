"""The live view (a Foxglove WebSocket server) and MCAP recording of the cell (issue 17)."""

from __future__ import annotations

from enum import StrEnum

from pydantic import Field, model_validator

from services.common.settings.base import Model, is_loopback


class McapCompression(StrEnum):
    ZSTD = "zstd"
    LZ4 = "lz4"
    NONE = "none"


class FoxgloveSettings(Model):
    """The Foxglove WebSocket server (``foxglove.sdk.v1``, the renamed ``foxglove.websocket.v1``)."""

    enabled: bool = True
    host: str = "127.0.0.1"
    port: int = Field(8765, ge=0, le=65535, description="0 = any free port")
    allow_remote: bool = Field(False, description="a non-loopback bind address needs this")
    tf_rate_hz: float = Field(
        50.0,
        ge=0,
        description="/tf at most this often on the controller's clock (50: every third 125 Hz joint state, "
        "~42 Hz; /tf is the recorder's largest CPU cost); 0 = one FrameTransforms per joint state",
    )
    robot_status_period_s: float = Field(0.5, gt=0, description="/robot/status at least this often")

    @model_validator(mode="after")
    def _loopback(self) -> FoxgloveSettings:
        if not self.allow_remote and not is_loopback(self.host):
            raise ValueError(
                f"record.foxglove.host {self.host!r} is not loopback (set record.foxglove.allow_remote)"
            )
        return self


class RecordSettings(Model):
    foxglove: FoxgloveSettings = FoxgloveSettings()
    dir: str | None = Field(None, description="record MCAP files here (`--record DIR`); None = off")
    max_file_bytes: int = Field(256 * 1024 * 1024, ge=4096, description="start a new file beyond this")
    max_file_s: float = Field(600.0, gt=0, description="start a new file after this long")
    compression: McapCompression = McapCompression.ZSTD
    chunk_bytes: int = Field(1024 * 1024, ge=1024, description="uncompressed size of an MCAP chunk")
    camera_rate_hz: float = Field(
        1.0, gt=0, description="camera frames recorded per second (the live view shows every frame)"
    )
    depth: bool = Field(True, description="record /camera/depth (16UC1, lossless) beside the colour")
    jpeg_quality: int = Field(90, ge=10, le=100, description="/camera/color JPEG quality")
    queue_size: int = Field(4096, ge=16, description="messages waiting for the converter before drops")
    ros2_joint_states: bool = Field(
        False,
        description="the joint states also as ROS 2 sensor_msgs/msg/JointState (CDR) on /ros2/joint_states, "
        "for ROS 2 tools (costs ~0.1-0.3 ms of CPU per 125 Hz state)",
    )
