"""The one place where Zenoh key expressions are named.

Every stream lives under ``pickplace/<cell_id>/…``; payloads are the protobuf
messages of ``proto/`` serialised.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

ROOT = "pickplace"

# the high-rate streams, under the cell's prefix
JOINT_STATES = "robot/joint_states"
CAMERA_FRAMES = "camera/rgbd"
VISION_DEBUG_IMAGE = "vision/debug_jpeg"


class Lane(enum.Enum):
    """Which zenoh priority queue a key's samples wait in on a congested link (none ever blocks)."""

    STREAM = enum.auto()  # a high-rate stream: a late sample is worth nothing
    AHEAD = enum.auto()  # records, commands, state changes: a queue of their own, sent first


def lane(key: str) -> Lane:
    """The lane of ``key`` (``pickplace/<cell_id>/<tail>``): all but the high-rate streams go AHEAD."""
    tail = key.split("/", 2)[-1]
    return Lane.STREAM if tail in (JOINT_STATES, CAMERA_FRAMES, VISION_DEBUG_IMAGE) else Lane.AHEAD


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
        return f"{self.prefix}/{JOINT_STATES}"

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
        return f"{self.prefix}/{CAMERA_FRAMES}"

    @property
    def camera_frame_requests(self) -> str:
        """An empty sample: a frame is wanted now (a detection the task waits for). A simulated camera
        renders at once instead of at its next period; a real one streams at its own rate and ignores it."""
        return f"{self.prefix}/camera/request"

    @property
    def detected_objects(self) -> str:
        return f"{self.prefix}/vision/objects"

    @property
    def vision_debug_image(self) -> str:
        return f"{self.prefix}/{VISION_DEBUG_IMAGE}"

    # task
    @property
    def task_status(self) -> str:
        return f"{self.prefix}/task/status"

    @property
    def pick_events(self) -> str:
        return f"{self.prefix}/task/picks"

    @property
    def pick_progress(self) -> str:
        """pickplace.v1.PickEvent with status RUNNING: a cycle's record when it starts and at each stage it
        reaches (its outcome goes to :attr:`pick_events`, once)."""
        return f"{self.prefix}/task/pick_progress"

    @property
    def task_plans(self) -> str:
        """pickplace.v1.TaskPlan: every plan the task gets from motion (tool path and planning scene)."""
        return f"{self.prefix}/task/plans"

    @property
    def task_commands(self) -> str:
        return f"{self.prefix}/task/commands"

    # the simulated cell (its own process)
    @property
    def sim_scene_reset(self) -> str:
        """A Zenoh query: lay out a fresh seeded scene (payload ``{"seed": n}`` or empty for the next);
        the reply ``{"seed": n}`` comes once frames show it."""
        return f"{self.prefix}/sim/reset_scene"

    # configuration
    @property
    def config_updates(self) -> str:
        """pickplace.v1.ConfigUpdate: the gateway's accepted PUT /config changes (on each PUT and periodically)."""
        return f"{self.prefix}/config/updates"

    @property
    def all(self) -> str:
        return f"{self.prefix}/**"
