"""Recovery decisions of LLD §15.2, from the failed step (pure).

Given the error a state raised and how often each kind of retry has been used in
this cycle, say what to do next. The orchestrator carries it out.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from services.common.errors import (
    ControllerError,
    GraspFailureError,
    ObjectNotDetectedError,
    PathDeviationError,
    PlanningError,
    RobotCommunicationError,
    SafetyError,
    VisionError,
)


class Action(enum.StrEnum):
    RETRY_DETECT = "retry_detect"  # DETECT_FAILED → RETRY: look again
    NEXT_GRASP = "next_grasp"  # replan with a different grasp / approach
    CLEAR_AND_RESUME = "clear_and_resume"  # clear the robot alarm, replan from here, go on
    REGRASP = "regrasp"  # open, back off, re-detect, grasp again (adjusted)
    WAIT_FOR_OPERATOR = "wait_for_operator"  # safety: stop everything
    ABORT = "abort"  # give up on this object, leave the robot safe


@dataclass(frozen=True)
class RetryLimits:
    detect: int = 3
    grasp_variants: int = 4
    alarms: int = 2
    regrasps: int = 2


@dataclass
class Attempts:
    detect: int = 0
    grasp_variants: int = 0
    alarms: int = 0
    regrasps: int = 0
    history: list[str] = field(default_factory=list)

    @property
    def total(self) -> int:
        return 1 + self.grasp_variants + self.alarms + self.regrasps


# (errors, the retry counter they spend, what to do while it lasts); first match wins, so the
# specific errors come before their base classes (ObjectNotDetectedError is a VisionError).
_RULES: tuple[tuple[type[BaseException] | tuple[type[BaseException], ...], str, Action], ...] = (
    (ObjectNotDetectedError, "detect", Action.RETRY_DETECT),
    (GraspFailureError, "regrasps", Action.REGRASP),
    (PlanningError, "grasp_variants", Action.NEXT_GRASP),
    ((ControllerError, RobotCommunicationError), "alarms", Action.CLEAR_AND_RESUME),
    (VisionError, "detect", Action.RETRY_DETECT),
)


def _budget(limits: RetryLimits, counter: str) -> int:
    # grasp_variants limits the plans tried in all, the first one included; the others count retries
    return getattr(limits, counter) - (1 if counter == "grasp_variants" else 0)


def decide(
    error: BaseException,
    attempts: Attempts,
    limits: RetryLimits,
    *,
    holding: bool = False,
    another_grasp: bool = False,
) -> Action:
    """The next action after ``error``; also counts the attempt it spends.

    ``another_grasp``: the failed step cannot be mended by doing it again (a grasp approach that met
    something again after it was raised: not the table but a neighbour the fingers press on; one the
    execution monitor stopped off its path): a controller error or a path deviation then spends a grasp
    option instead of an alarm retry or the end of the cycle.

    ``holding``: the failed step carries the object (the gripper closed on it). A plan that cannot be
    made from there is not traded for another grasp, which backs off with the jaws open and would drop
    the object wherever the arm stands, then look for it on the table: the cycle gives up with the arm
    stopped and the object still held (an alarm is still cleared and the carry resumed).
    """
    attempts.history.append(f"{type(error).__name__}: {error}")
    if isinstance(error, SafetyError):
        return Action.WAIT_FOR_OPERATOR
    if another_grasp and isinstance(error, ControllerError | PathDeviationError) and not holding:
        if attempts.grasp_variants < _budget(limits, "grasp_variants"):
            attempts.grasp_variants += 1
            return Action.NEXT_GRASP
        return Action.ABORT
    for kinds, counter, action in _RULES:
        if isinstance(error, kinds):
            if holding and action is Action.NEXT_GRASP:
                return Action.ABORT
            used = getattr(attempts, counter)
            if used < _budget(limits, counter):
                setattr(attempts, counter, used + 1)
                return action
            return Action.ABORT
    return Action.ABORT  # InvalidInputError, any other RobotError, anything unexpected
