"""Dobot V4 codes of the manual: robot modes, command ErrorIDs, controller alarms, and their texts."""

from __future__ import annotations

import enum


class RobotMode(enum.IntEnum):
    INIT = 1
    BRAKE_OPEN = 2
    POWER_OFF = 3
    DISABLED = 4
    ENABLE = 5  # enabled and idle
    BACKDRIVE = 6
    RUNNING = 7
    SINGLE_MOVE = 8
    ERROR = 9
    PAUSE = 10
    COLLISION = 11

    @classmethod
    def name_of(cls, value: int) -> str:
        try:
            return cls(value).name
        except ValueError:
            return f"UNKNOWN({value})"


class ErrorID(enum.IntEnum):
    OK = 0
    FAILED = -1
    ALARM = -2
    ESTOP = -3
    POWERED_OFF = -4
    SCRIPT_RUNNING = -5
    JOG_MISMATCH = -6
    SCRIPT_PAUSED = -7
    LICENCE = -8
    UNKNOWN_COMMAND = -10000
    PARAM_COUNT = -20000
    # -3000X type / -4000X range of required parameter X; -5000X / -6000X of optional ones
    REQUIRED_TYPE = -30000
    REQUIRED_RANGE = -40000
    OPTIONAL_TYPE = -50000
    OPTIONAL_RANGE = -60000


ERROR_ID_TEXT = {
    0: "accepted",
    -1: "received but failed to execute",
    -2: "robot is in alarm state (clear the alarm and resend)",
    -3: "robot is in emergency-stop state (release the e-stop, clear, resend)",
    -4: "robot is powered off",
    -5: "a script is running; command refused",
    -6: "jog axis and coordinate type mismatch",
    -7: "a script is paused; command refused",
    -8: "controller licence expired",
    -10000: "unknown command",
    -20000: "wrong number of parameters",
}


def describe_error_id(error_id: int) -> str:
    if error_id in ERROR_ID_TEXT:
        return ERROR_ID_TEXT[error_id]
    for base, what in (
        (-30000, "wrong type of required parameter"),
        (-40000, "required parameter out of range"),
        (-50000, "wrong type of optional parameter"),
        (-60000, "optional parameter out of range"),
    ):
        if base - 9 <= error_id <= base - 1:
            return f"{what} {base - error_id}"
    return f"error {error_id}"


class Alarm(enum.IntEnum):
    """Controller alarm IDs that motion code reacts to (GetErrorID)."""

    SHOULDER_SINGULARITY = 16
    IK_NO_SOLUTION = 17
    IK_OUT_OF_WORKSPACE = 18
    WRIST_SINGULARITY = 26
    ELBOW_SINGULARITY = 27
    SPEED_PARAMETER = 29
    FULL_IK_FAILED = 30
    ENABLE_FAILED = 115
    ESTOP_PRESSED = 116
    COLLISION = 117


ALARM_TEXT = {
    16: "planned point near the shoulder singularity",
    17: "inverse kinematics has no solution",
    18: "IK result out of the working area",
    26: "near the wrist singularity",
    27: "near the elbow singularity",
    29: "speed parameter wrong",
    30: "full-parameter IK failed",
    115: "enable failed",
    116: "emergency stop button pressed",
    117: "collision detected",
}


def joint_overspeed_alarm(joint_index: int) -> int:
    """48..53: joint 1..6 overspeed (joint_index 0-based)."""
    return 48 + joint_index


def joint_limit_alarm(joint_index: int, positive: bool) -> int:
    """64..75: J1 positive, J1 negative, ..., J6 negative (joint_index 0-based)."""
    return 64 + 2 * joint_index + (0 if positive else 1)


def describe_alarm(alarm_id: int) -> str:
    if alarm_id in ALARM_TEXT:
        return ALARM_TEXT[alarm_id]
    if 48 <= alarm_id <= 53:
        return f"joint {alarm_id - 47} overspeed"
    if 64 <= alarm_id <= 75:
        j, neg = divmod(alarm_id - 64, 2)
        return f"joint {j + 1} {'negative' if neg else 'positive'} limit"
    return f"alarm {alarm_id}"
