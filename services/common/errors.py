"""The one error hierarchy of pickplace (LLD §15.1).

Every service raises these; they cross gRPC as status codes carrying the
error's class name (see :mod:`services.common.grpc_util`) and reach REST users
as JSON bodies. Messages say what was wrong and with which value.
"""

from __future__ import annotations

import grpc


class RobotError(Exception):
    """Root of every pickplace error."""

    grpc_code: grpc.StatusCode = grpc.StatusCode.INTERNAL


# --- input and configuration -------------------------------------------------
class InvalidInputError(RobotError, ValueError):
    """A request or argument is malformed (wrong shape, NaN, out of range)."""

    grpc_code = grpc.StatusCode.INVALID_ARGUMENT


class StartMismatchError(InvalidInputError):
    """A trajectory that does not start where the arm is (or where the motion it continues ends):
    nothing was sent; plan it again from the current state."""


class ConfigurationError(RobotError):
    """Settings are missing, inconsistent or unsafe."""

    grpc_code = grpc.StatusCode.FAILED_PRECONDITION


# --- vision -------------------------------------------------------------------
class VisionError(RobotError):
    grpc_code = grpc.StatusCode.INTERNAL


class CameraConnectionError(VisionError):
    grpc_code = grpc.StatusCode.UNAVAILABLE


class ObjectNotDetectedError(VisionError):
    grpc_code = grpc.StatusCode.NOT_FOUND


class PoseEstimationError(VisionError):
    pass


# --- planning -----------------------------------------------------------------
class PlanningError(RobotError):
    grpc_code = grpc.StatusCode.FAILED_PRECONDITION


class IKFailureError(PlanningError):
    pass


class CollisionError(PlanningError):
    pass


class PathPlanningTimeoutError(PlanningError):
    grpc_code = grpc.StatusCode.DEADLINE_EXCEEDED


class TrajectoryLimitError(PlanningError):
    """A trajectory exceeds a joint position, velocity or acceleration limit."""


# --- execution ----------------------------------------------------------------
class ExecutionError(RobotError):
    grpc_code = grpc.StatusCode.ABORTED


class TrajectoryExecutionError(ExecutionError):
    pass


class GraspFailureError(ExecutionError):
    pass


class PathDeviationError(ExecutionError):
    """The execution monitor stopped the arm: it left its planned path (or the controller's reference) by
    more than the path tolerance, or settled off the path's end by more than the goal tolerance, as when
    something pushes on it. At a grasp approach: the fingers on the object's edge or on a neighbour, and
    another grasp is planned."""


class RobotBusyError(ExecutionError):
    """The arm is executing another motion: one stream at a time, a second request is refused, not queued."""

    grpc_code = grpc.StatusCode.FAILED_PRECONDITION


class CycleInterruptedError(ExecutionError):
    """A pick cycle cut short by a crashed process or the operator's stop, not by a failure of its
    own; the pick's record is marked interrupted at the stage it had reached."""


class ControllerError(ExecutionError):
    """The robot controller refused a command or raised an alarm."""

    def __init__(self, message: str, *, error_id: int | None = None, alarms: tuple[int, ...] = ()):
        super().__init__(message)
        self.error_id = error_id
        self.alarms = alarms


class ContactAlarmError(ControllerError):
    """The controller stopped the arm on a contact its collision detection felt (Dobot alarm 117): the arm
    rests where it touched. Cleared like any alarm; a grasp approach that touched is retried higher."""


# --- hardware -----------------------------------------------------------------
class HardwareError(RobotError):
    grpc_code = grpc.StatusCode.UNAVAILABLE


class RobotCommunicationError(HardwareError):
    pass


class GripperError(HardwareError):
    pass


class SensorError(HardwareError):
    pass


# --- safety -------------------------------------------------------------------
class SafetyError(RobotError):
    grpc_code = grpc.StatusCode.FAILED_PRECONDITION


class CollisionDetectedError(SafetyError):
    pass


class ForceExceededError(SafetyError):
    pass


class EmergencyStopError(SafetyError):
    pass


class LimitViolationError(SafetyError):
    """A command would leave joint, velocity or workspace limits; it was not sent."""


class ContinuationLateError(LimitViolationError):
    """A trajectory that continues a motion in flight came after that motion had ended (the arm is at
    rest, the trajectory starts moving): streamed as it is it would be a step in speed. Nothing was
    sent; plan it again from rest."""


def _all_subclasses(cls: type[RobotError]) -> dict[str, type[RobotError]]:
    found: dict[str, type[RobotError]] = {cls.__name__: cls}
    for sub in cls.__subclasses__():
        found.update(_all_subclasses(sub))
    return found


def error_class(name: str) -> type[RobotError]:
    """Look an error class up by name (used when an error comes back over a transport)."""
    return _all_subclasses(RobotError).get(name, RobotError)


class InvalidFrameError(InvalidInputError, VisionError):
    """A frame the vision cores cannot use: wrong shapes or types, NaN intrinsics, no depth."""

    grpc_code = InvalidInputError.grpc_code
