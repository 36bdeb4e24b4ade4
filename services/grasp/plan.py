"""Waypoint plans the grasp service hands to the task: what to move to, how, and the gripper.

Tool frame convention (the twin's, ``services/sim/twin/mjcf.py``): ``tool_tip`` is the grasp
centre between the pads, tool +z points out of the flange (the approach direction), the jaws
close along tool y. A waypoint's gripper action runs *after* the arm reaches it. A guarded
waypoint is approached along a straight line and the motion stops early as the wrist
force drops by ``force_drop_n`` (the object touched down); it may go ``overtravel_m`` past the
nominal pose if it has not touched yet. ``hold`` means no motion: act where the arm stands
(release at touch height, do not push down — the twin notes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from services.common.modes import GripperCommand, MotionKind, TaskKind

Array = np.ndarray


@dataclass(frozen=True)
class Guard:
    """A guarded move: stop on touch-down, read as a drop of the wrist force along base z."""

    force_drop_n: float
    overtravel_m: float
    speed_m_s: float
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)  # base frame
    # two-stage: at approach_speed_m_s until slow_band_m above the nominal contact (0: slow all the way)
    slow_band_m: float = 0.0
    approach_speed_m_s: float = 0.0


@dataclass(frozen=True)
class HeldObject:
    """The object in the gripper, for collision checks while carrying it (motion's AttachedObject)."""

    shape: Literal["cylinder", "box"]
    T_tool_object: Array
    radius: float = 0.0  # cylinder (axis = object z)
    length: float = 0.0
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)  # box


@dataclass(frozen=True)
class Waypoint:
    name: str
    T_base_tool: Array
    motion: MotionKind
    q: Array  # joints (rad) of the planned IK branch at this pose
    gripper: GripperCommand | None = None
    guard: Guard | None = None
    holding: bool = False  # the object is in the gripper on the way to this waypoint

    @property
    def guarded(self) -> bool:
        return self.guard is not None


@dataclass(frozen=True)
class Grasp:
    """One grasp: tool pose at closing, opening, quality and force-closure figures."""

    T_base_tool: Array
    width_m: float  # object width between the pads
    opening_m: float  # commanded opening before closing
    quality: float  # [0, 1] ranking score
    width_quality: float  # LLD §4.2 score: 1 − |w/w_max − 0.5|·0.5
    epsilon: float  # Ferrari–Canny ε (0 = no force closure)
    force_closure: bool
    approach_direction: Array  # unit, base frame (tool z)
    approach_distance_m: float
    force_n: float
    q: Array | None = None  # an IK solution (nearest the seed) when reachability was checked
    contacts_base: Array | None = None  # (k, 3) contact points in the base frame
    label: str = ""


@dataclass(frozen=True)
class PickPlan:
    task: TaskKind
    waypoints: tuple[Waypoint, ...]
    grasp: Grasp
    held: HeldObject
    place_position: Array  # base frame: rod base centre / cube bottom centre at placement
    notes: dict[str, float | str] = field(default_factory=dict)

    def names(self) -> list[str]:
        return [w.name for w in self.waypoints]

    def waypoint(self, name: str) -> Waypoint:
        for w in self.waypoints:
            if w.name == name:
                return w
        raise KeyError(f"plan has no waypoint {name!r}; it has {self.names()}")
