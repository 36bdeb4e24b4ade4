"""The one place where Zenoh key expressions are named.

Every stream lives under ``pickplace/<cell_id>/…``; payloads are the protobuf
messages of ``proto/`` serialised.
"""

from __future__ import annotations

from dataclasses import dataclass

ROOT = "pickplace"


@dataclass(frozen=True)
class CellKeys:
    cell_id: str

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.cell_id}"

    # robot driver
    @property
    def joint_states(self) -> str:
        """pickplace.v1.JointState at the feedback rate."""
        return f"{self.prefix}/robot/joint_states"

    @property
    def robot_status(self) -> str:
        """pickplace.v1.RobotStatus on every mode change and at 2 Hz."""
        return f"{self.prefix}/robot/status"

    @property
    def robot_events(self) -> str:
        return f"{self.prefix}/robot/events"

    # camera and vision
    @property
    def camera_frames(self) -> str:
        return f"{self.prefix}/camera/rgbd"

    @property
    def detected_objects(self) -> str:
        return f"{self.prefix}/vision/objects"

    @property
    def vision_debug_image(self) -> str:
        return f"{self.prefix}/vision/debug_jpeg"

    # task
    @property
    def task_status(self) -> str:
        return f"{self.prefix}/task/status"

    @property
    def pick_events(self) -> str:
        return f"{self.prefix}/task/picks"

    @property
    def task_commands(self) -> str:
        return f"{self.prefix}/task/commands"

    # configuration
    @property
    def config_updates(self) -> str:
        """pickplace.v1.ConfigUpdate: the gateway's accepted PUT /config changes (on each PUT and periodically)."""
        return f"{self.prefix}/config/updates"

    @property
    def all(self) -> str:
        return f"{self.prefix}/**"
