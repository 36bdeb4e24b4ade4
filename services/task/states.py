"""Cycle states (seed 001 / LLD §7.3) and the data the orchestrator reports (pure)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from services.task.pacing import LinePace


class CycleState(enum.StrEnum):
    IDLE = "IDLE"
    INIT = "INIT"
    DETECT = "DETECT"
    DETECT_FAILED = "DETECT_FAILED"
    RETRY = "RETRY"
    PLAN = "PLAN"
    APPROACH = "APPROACH"
    GRASP = "GRASP"
    LIFT = "LIFT"
    REORIENT = "REORIENT"
    TRANSPORT = "TRANSPORT"  # cube sorting: carry to the drop zone
    PLACE = "PLACE"
    RELEASE = "RELEASE"
    DONE = "DONE"
    ABORT = "ABORT"
    STOPPED = "STOPPED"
    ESTOP = "ESTOP"
    ERROR = "ERROR"


# Progress through one cycle, for the status bar.
PROGRESS = {
    CycleState.INIT: 0.0,
    CycleState.DETECT: 0.05,
    CycleState.DETECT_FAILED: 0.05,
    CycleState.RETRY: 0.05,
    CycleState.PLAN: 0.15,
    CycleState.APPROACH: 0.25,
    CycleState.GRASP: 0.4,
    CycleState.LIFT: 0.5,
    CycleState.REORIENT: 0.6,
    CycleState.TRANSPORT: 0.6,
    CycleState.PLACE: 0.75,
    CycleState.RELEASE: 0.9,
    CycleState.DONE: 1.0,
}


# The states of a cycle under way (DONE: the arm only goes home; a cell idles there after its last).
ACTIVE_STATES = frozenset(PROGRESS) - {CycleState.DONE}


@dataclass(frozen=True)
class StateDeadlines:
    """Budget of each state (s); exceeding it fails the state with a timeout. Detection and planning
    are compute, timed on the wall clock; motion and gripper deadlines run on the controller clock."""

    detect_s: float = 10.0
    plan_s: float = 20.0
    motion_s: float = 60.0
    gripper_s: float = 10.0


@dataclass
class PickOutcome:
    """One pick attempt, as reported on the bus and stored by the gateway."""

    pick_id: str
    task: str
    object_class: str = ""
    object_id: str = ""
    success: bool = False
    stage_reached: str = CycleState.INIT.value
    failure_reason: str = ""
    error_code: str = ""
    attempts: int = 1
    cycle_time_s: float = 0.0  # on the orchestrator's clock: the controller's in the cell
    grasp_quality: float = 0.0
    pick_pose: list[float] | None = None  # x, y, z, qx, qy, qz, qw (base frame, m)
    place_pose: list[float] | None = None
    stage_durations_s: dict[str, float] = field(default_factory=dict)  # on the orchestrator's clock
    stage_wall_s: dict[str, float] = field(default_factory=dict)  # the same states in wall time
    executed_waypoints: list[list[float]] = field(default_factory=list)  # joints (rad) the arm went through
    executed_rests: list[bool] = field(default_factory=list)  # per waypoint: the arm came to rest there
    # per waypoint where a paced guarded line ended (its index above): the caps it went under
    executed_paces: dict[int, LinePace] = field(default_factory=dict)
    gripper_actions: int = 0
    gripper_releases: int = 0  # of those, opens that let go of a held object (answered when clear of it)
    # what the arm waited for to be computed outside DETECT and PLAN (a held rod measured before the
    # touch-down), on the orchestrator's clock and in wall time
    inline_compute_s: float = 0.0
    inline_compute_wall_s: float = 0.0


@dataclass
class TaskCounters:
    picks_completed: int = 0
    picks_failed: int = 0
    cycle_times_s: list[float] = field(default_factory=list)

    @property
    def average_cycle_time(self) -> float:
        return sum(self.cycle_times_s) / len(self.cycle_times_s) if self.cycle_times_s else 0.0

    @property
    def success_rate(self) -> float:
        n = self.picks_completed + self.picks_failed
        return self.picks_completed / n if n else 0.0

    def record(self, outcome: PickOutcome) -> None:
        if outcome.success:
            self.picks_completed += 1
            self.cycle_times_s.append(outcome.cycle_time_s)
        else:
            self.picks_failed += 1
