"""Recovery decisions (LLD §15.2): which error spends which retry, and when it gives up."""

from __future__ import annotations

from services.common.errors import (
    CollisionError,
    ControllerError,
    GraspFailureError,
    InvalidInputError,
    ObjectNotDetectedError,
    SafetyError,
    VisionError,
)
from services.task.recovery import Action, Attempts, RetryLimits, decide

LIMITS = RetryLimits(detect=2, grasp_variants=3, alarms=1, regrasps=1)


def actions(error: Exception, n: int) -> list[Action]:
    attempts = Attempts()
    return [decide(error, attempts, LIMITS) for _ in range(n)]


def test_each_error_spends_its_own_retries_then_aborts() -> None:
    assert actions(ObjectNotDetectedError("no rod"), 3) == [Action.RETRY_DETECT] * 2 + [Action.ABORT]
    assert actions(VisionError("camera hiccup"), 3) == [Action.RETRY_DETECT] * 2 + [Action.ABORT]
    # grasp_variants counts the plans tried in all: 3 plans = the first + 2 more
    assert actions(CollisionError("cube in the way"), 3) == [Action.NEXT_GRASP] * 2 + [Action.ABORT]
    assert actions(GraspFailureError("slipped"), 2) == [Action.REGRASP, Action.ABORT]
    assert actions(ControllerError("alarm 117"), 2) == [Action.CLEAR_AND_RESUME, Action.ABORT]


def test_safety_always_waits_for_the_operator_and_bad_input_aborts() -> None:
    assert actions(SafetyError("e-stop"), 3) == [Action.WAIT_FOR_OPERATOR] * 3
    assert actions(InvalidInputError("NaN pose"), 1) == [Action.ABORT]


def test_counters_are_shared_per_kind_and_history_keeps_every_error() -> None:
    attempts = Attempts()
    decide(ObjectNotDetectedError("a"), attempts, LIMITS)
    decide(VisionError("b"), attempts, LIMITS)  # the same detect budget
    assert decide(VisionError("c"), attempts, LIMITS) is Action.ABORT
    assert attempts.detect == 2 and len(attempts.history) == 3
    assert attempts.history[0] == "ObjectNotDetectedError: a"
