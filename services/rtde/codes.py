"""The numbers of the UR RTDE interface, the dashboard server and ur_rtde's control script, as enums.

Sources (docs/ur/rtde.md cites each): UR's "Real-Time Data Exchange (RTDE) Guide" (message types,
field types, robot/safety modes, runtime state, status bits) and SDU's ur_rtde 1.5.8 sources
(``include/ur_rtde/rtde.h`` RobotCommand::Type, ``rtde_control_interface.h`` register protocol,
``scripts/rtde_control.script``).
"""

from __future__ import annotations

import enum


class MessageType(enum.IntEnum):
    """The RTDE package types (the third header byte): ASCII letters."""

    REQUEST_PROTOCOL_VERSION = 86  # 'V'
    GET_URCONTROL_VERSION = 118  # 'v'
    TEXT_MESSAGE = 77  # 'M'
    DATA_PACKAGE = 85  # 'U'
    CONTROL_PACKAGE_SETUP_OUTPUTS = 79  # 'O'
    CONTROL_PACKAGE_SETUP_INPUTS = 73  # 'I'
    CONTROL_PACKAGE_START = 83  # 'S'
    CONTROL_PACKAGE_PAUSE = 80  # 'P'


class URRobotMode(enum.IntEnum):
    """RTDE ``robot_mode`` (and the dashboard's ``robotmode`` words)."""

    NO_CONTROLLER = -1
    DISCONNECTED = 0
    CONFIRM_SAFETY = 1
    BOOTING = 2
    POWER_OFF = 3
    POWER_ON = 4
    IDLE = 5
    BACKDRIVE = 6
    RUNNING = 7
    UPDATING_FIRMWARE = 8


class SafetyMode(enum.IntEnum):
    """RTDE ``safety_mode`` (and the dashboard's ``safetystatus`` words)."""

    NORMAL = 1
    REDUCED = 2
    PROTECTIVE_STOP = 3
    RECOVERY = 4
    SAFEGUARD_STOP = 5
    SYSTEM_EMERGENCY_STOP = 6
    ROBOT_EMERGENCY_STOP = 7
    VIOLATION = 8
    FAULT = 9
    VALIDATE_JOINT_ID = 10
    UNDEFINED_SAFETY_MODE = 11
    AUTOMATIC_MODE_SAFEGUARD_STOP = 12
    SYSTEM_THREE_POSITION_ENABLING_STOP = 13


class RuntimeState(enum.IntEnum):
    """RTDE ``runtime_state``: the program's state."""

    STOPPING = 0
    STOPPED = 1
    PLAYING = 2
    PAUSING = 3
    PAUSED = 4
    RESUMING = 5


class RobotStatusBit(enum.IntFlag):
    """RTDE ``robot_status_bits``."""

    POWER_ON = 1 << 0
    PROGRAM_RUNNING = 1 << 1
    TEACH_BUTTON_PRESSED = 1 << 2
    POWER_BUTTON_PRESSED = 1 << 3


class SafetyStatusBit(enum.IntFlag):
    """RTDE ``safety_status_bits``."""

    NORMAL_MODE = 1 << 0
    REDUCED_MODE = 1 << 1
    PROTECTIVE_STOPPED = 1 << 2
    RECOVERY_MODE = 1 << 3
    SAFEGUARD_STOPPED = 1 << 4
    SYSTEM_EMERGENCY_STOPPED = 1 << 5
    ROBOT_EMERGENCY_STOPPED = 1 << 6
    EMERGENCY_STOPPED = 1 << 7
    VIOLATION = 1 << 8
    FAULT = 1 << 9
    STOPPED_DUE_TO_SAFETY = 1 << 10


class ScriptCommand(enum.IntEnum):
    """ur_rtde's command numbers, written to ``input_int_register_0`` (+offset) for its control script."""

    NO_CMD = 0
    MOVEJ = 1
    MOVEJ_IK = 2
    MOVEL = 3
    MOVEL_FK = 4
    FORCE_MODE = 6
    FORCE_MODE_STOP = 7
    ZERO_FT_SENSOR = 8
    SPEEDJ = 9
    SPEEDL = 10
    SERVOJ = 11
    SERVOC = 12
    SET_STD_DIGITAL_OUT = 13
    SET_TOOL_DIGITAL_OUT = 14
    SPEED_STOP = 15
    SERVO_STOP = 16
    SET_PAYLOAD = 17
    TEACH_MODE = 18
    END_TEACH_MODE = 19
    SERVOL = 24
    TOOL_CONTACT = 25
    GET_STEPTIME = 26
    GET_ACTUAL_JOINT_POSITIONS_HISTORY = 27
    SET_TCP = 29
    PROTECTIVE_STOP = 31
    STOPL = 33
    STOPJ = 34
    SET_WATCHDOG = 35
    GET_JOINT_TORQUES = 38
    MOVE_PATH = 45
    IS_STEADY = 47
    WATCHDOG = 99
    STOP_SCRIPT = 255


# The script's real-time commands: processed and answered "ready" at once, every cycle
# (rtde_control.script main loop; ur_rtde's sendCommand does not wait for "done" on them).
REALTIME_COMMANDS = frozenset({6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71})


class ScriptState(enum.IntEnum):
    """What the control script writes to ``output_int_register_0`` (+offset)."""

    RUNNING_CMD = 0  # initial value, before the script signals
    READY_FOR_CMD = 1  # UR_CONTROLLER_RDY_FOR_CMD
    DONE_WITH_CMD = 2  # UR_CONTROLLER_DONE_WITH_CMD


ASYNC_RUNNING_BIT = 1 << 15  # output_int_register_2: an async operation is running
