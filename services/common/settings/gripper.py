"""The parallel-jaw gripper on the controller's digital outputs."""

from __future__ import annotations

from pydantic import Field

from services.common.settings.base import Model


class GripperSettings(Model):
    """Parallel-jaw gripper on controller digital outputs."""

    close_do: int = Field(1, ge=1, le=1000, description="DO index that closes the jaws when ON")
    open_do: int | None = Field(2, ge=1, le=1000, description="DO that opens (None: close_do OFF opens)")
    tool_outputs: bool = Field(False, description="use the flange ToolDO instead of the cabinet DO")
    actuation_time_s: float = Field(0.4, ge=0, le=10)
    # An open that lets go of a held object answers once the jaws are clear of it, not fully open: the
    # arm may move away then. The twin's fingers open at 0.1 m/s each: 0.12 s is 12 mm a side.
    release_time_s: float = Field(
        0.12, ge=0, le=10, description="controller time from an open until the jaws let go of the object"
    )
    object_di: int | None = Field(None, ge=1, le=1000, description="DI that reads 1 when holding")
    stroke_m: float = Field(0.085, gt=0, le=0.3)
    # Flange → grasp centre (between the pads) along the flange z axis; shared by motion and the twin.
    tcp_offset_m: float = Field(0.16, gt=0, le=0.5)

    @property
    def release_wait_s(self) -> float:
        """How long a release waits: ``release_time_s``, never longer than a full stroke."""
        return min(self.release_time_s, self.actuation_time_s)
