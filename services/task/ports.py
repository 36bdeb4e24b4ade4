"""What the orchestrator needs from the rest of the cell, as small async interfaces.

The task service implements these over gRPC (``clients.py``); tests may inject
scripted fakes. Everything is in the base frame, SI units.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from services.common.errors import InvalidInputError
from services.common.frames import tilt_from_vertical_deg
from services.common.modes import GripperCommand, MotionKind, TaskKind
from services.kinematics.trajectory import JointTrajectory


@dataclass(frozen=True)
class SeenRod:
    center: np.ndarray  # m, base frame
    axis: np.ndarray  # unit
    length: float
    diameter: float
    confidence: float


@dataclass(frozen=True)
class SeenCube:
    centroid: np.ndarray
    color: str
    size: float = 0.05


@dataclass(frozen=True)
class SeenBox:
    min: np.ndarray
    max: np.ndarray


@dataclass(frozen=True)
class Observation:
    rods: tuple[SeenRod, ...] = ()
    cubes: tuple[SeenCube, ...] = ()
    obstacles: tuple[SeenBox, ...] = ()
    notes: tuple[str, ...] = ()
    latency_ms: float = 0.0


@dataclass(frozen=True)
class MoveOutcome:
    final_q: np.ndarray
    duration_s: float
    stopped_early: bool = False


@dataclass(frozen=True)
class GripOutcome:
    closed: bool
    object_detected: bool | None
    unchanged: bool = False  # the jaws were already as asked: no actuation (an open of open jaws)


@dataclass
class PlannedWaypoint:
    name: str
    motion: MotionKind
    T_base_tool: np.ndarray
    joints: np.ndarray
    gripper: GripperCommand | None = None  # after the arm has reached the waypoint
    guard_force_n: float = 0.0
    guard_overtravel_m: float = 0.0
    guard_direction: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -1.0]))
    guard_speed_m_s: float = 0.0
    guard_slow_band_m: float = 0.0  # two-stage touch-down: slow only this far above the nominal contact
    guard_approach_speed_m_s: float = 0.0  # and this fast above it
    holding: bool = False


@dataclass
class GraspPlan:
    task: TaskKind
    waypoints: list[PlannedWaypoint]
    quality: float
    held_object: object | None  # motion's AttachedObject message, sent while holding
    place_position: np.ndarray
    summary: str = ""


@dataclass(frozen=True)
class HeldRodQuery:
    """Where a held rod should hang: within ``search_radius_m`` of the line through ``point`` along
    ``direction``, ``along_min_m..along_max_m`` along it, less the band ``skip_min_m..skip_max_m``."""

    point: np.ndarray
    direction: np.ndarray
    search_radius_m: float
    along_min_m: float
    along_max_m: float
    skip_min_m: float
    skip_max_m: float
    rod_diameter_m: float


@dataclass(frozen=True)
class SeenAxis:
    """A held rod's axis as vision measured it (``direction`` the query's way)."""

    direction: np.ndarray
    point: np.ndarray
    n_points: int

    @property
    def tilt_deg(self) -> float:
        return tilt_from_vertical_deg(self.direction)


class VisionPort(Protocol):
    async def observe(self) -> Observation: ...

    async def held_rod_axis(self, query: HeldRodQuery) -> SeenAxis:
        """The axis of the rod the gripper holds, on a frame taken now (ObjectNotDetectedError: too
        little of it seen)."""


class GraspPort(Protocol):
    async def plan_rod(
        self,
        rod: SeenRod,
        q_now: np.ndarray,
        obstacles: tuple[SeenBox, ...],
        alternative: int,
        place_xy: np.ndarray | None = None,
        grasp_offset_m: float | None = None,
        other_branches: bool = False,
    ) -> GraspPlan: ...

    async def plan_cube(
        self, cube: SeenCube, q_now: np.ndarray, obstacles: tuple[SeenBox, ...], alternative: int
    ) -> GraspPlan: ...


@dataclass(frozen=True)
class Move:
    """One move for the motion planner, in the scene and at the speed of that move."""

    kind: MotionKind  # JOINT: a joint-space move to joint positions; LINEAR: a straight tool line
    # JOINT: joint positions (rad), or a tool pose T_base_tool (4×4) reached by a joint move to its
    # collision-free IK solution nearest the start; LINEAR: the tool pose T_base_tool (4×4)
    target: np.ndarray
    held: object | None = None  # motion's AttachedObject, carried on this move
    slow: bool = False  # a guarded approach: at the touch-down speed scale
    table_contact: bool = False  # the held object may touch the table (lift-off, set-down)
    label: str = ""
    blend: bool = False  # the arm does not stop at this move's target: it flows into the next move
    blend_tolerance_m: float = 0.0  # with blend: how far the tool may cut the corner at the target
    obstacles: tuple[SeenBox, ...] = ()  # in this move's scene besides the plan's (what was placed)

    def __post_init__(self) -> None:
        pose = self.target.shape == (4, 4)
        shape = {MotionKind.JOINT: (self.target.ndim == 1 or pose), MotionKind.LINEAR: pose}
        if not shape.get(self.kind, False):
            raise InvalidInputError(
                f"move {self.label or 'unlabelled'}: a {self.kind} move needs "
                f"{'joint positions or a 4×4 tool pose' if self.kind is MotionKind.JOINT else 'a 4×4 tool pose'}, "
                f"got shape {self.target.shape}"
            )


class MotionPort(Protocol):
    async def plan_moves(
        self,
        start: np.ndarray,
        moves: Sequence[Move],
        obstacles: tuple[SeenBox, ...],
        start_velocity: np.ndarray | None = None,
    ) -> list[JointTrajectory | None]:
        """All ``moves`` in one request, each from where the previous one ends; one entry per move,
        None for a joint move to where the arm already is. ``start_velocity``: the arm moves at
        ``start`` (along the first move), and the first blended run is timed from that motion."""

    async def tool_pose(self, q: np.ndarray) -> np.ndarray: ...


class RobotPort(Protocol):
    async def joints(self) -> np.ndarray: ...

    async def execute(
        self, traj: JointTrajectory, force_guard_n: float = 0.0, continues: bool = False
    ) -> MoveOutcome:
        """``continues``: the trajectory ends in motion and the next one follows at once (answered
        when it is queued; ``final_q`` is then its last target)."""

    async def gripper(self, close: bool, release: bool = False) -> GripOutcome:
        """``release`` (an open): answered once the jaws have let go of the held object, not fully open."""

    async def holding(self) -> bool | None:
        """Whether the gripper's object sensor sees the object (None: no sensor mapped)."""

    async def holding_on_passing(self, q: np.ndarray) -> bool | None:
        """The object sensor in the joint state the controller reports as the arm passes ``q``
        (:class:`services.task.passing.PassWatch`), however much motion is queued ahead of it; None:
        no sensor mapped. Waits until then."""

    async def recover(self) -> None:
        """Clear alarms and enable."""

    async def stop(self) -> None: ...

    async def emergency_stop(self) -> None: ...


class ArmView(Protocol):
    """The arm against the camera: whether it leaves the view of the pick zone clear, and whether a
    box that vision saw is the arm itself (both by the camera and arm models, at joints ``q``)."""

    def clear(self, q: np.ndarray) -> bool: ...

    def holds_arm(self, q: np.ndarray, box_min: np.ndarray, box_max: np.ndarray) -> bool: ...
