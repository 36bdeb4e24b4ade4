"""One RTDE sample of a UR controller in the driver's terms (pure): SI units already, the controller's
``timestamp`` as ``timestamp_ms``, UR robot/safety modes mapped onto :class:`services.dobot.RobotMode`.

Mapping (docs/ur/rtde.md §6): e-stop → ``estop``; protective stop, violation or fault → ERROR (the
driver's alarm path: clear, re-enable); power off → POWER_OFF; powered with brakes locked, or brakes
released without ur_rtde's control script running → DISABLED (``enable`` releases / re-uploads);
running with the script → ENABLE, or RUNNING while a motion of the link is in progress.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.dobot import RobotMode
from services.robot.feedback import FeedbackState
from services.rtde.codes import RuntimeState, SafetyMode, SafetyStatusBit, URRobotMode
from services.rtde.poses import pose_to_transform

# The variables the link reads from RTDE (a recipe of its own, not ur_rtde's default 40).
RECEIVE_VARIABLES = [
    "timestamp",
    "actual_q",
    "actual_qd",
    "target_q",
    "actual_TCP_pose",
    "actual_TCP_force",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
    "runtime_state",
    "actual_digital_input_bits",
    "actual_digital_output_bits",
]

ERROR_SAFETY = (SafetyMode.PROTECTIVE_STOP, SafetyMode.VIOLATION, SafetyMode.FAULT)


@dataclass(frozen=True)
class URSample:
    timestamp_s: float
    q: tuple[float, ...]
    qd: tuple[float, ...]
    q_target: tuple[float, ...]
    tcp_pose: tuple[float, ...]
    tcp_force: tuple[float, ...]
    robot_mode: int
    safety_mode: int
    safety_status_bits: int
    runtime_state: int
    digital_inputs: int
    digital_outputs: int
    received_ns: int

    @property
    def estop(self) -> bool:
        return bool(self.safety_status_bits & SafetyStatusBit.EMERGENCY_STOPPED)

    @property
    def program_running(self) -> bool:
        return self.runtime_state == RuntimeState.PLAYING


def dobot_mode(s: URSample, moving: bool, estop_latched: bool) -> RobotMode:
    if s.safety_mode in ERROR_SAFETY:
        return RobotMode.ERROR
    if s.robot_mode == URRobotMode.POWER_OFF or s.estop or estop_latched:
        return RobotMode.POWER_OFF
    if s.robot_mode != URRobotMode.RUNNING or not s.program_running:
        return RobotMode.DISABLED
    return RobotMode.RUNNING if moving else RobotMode.ENABLE


def to_feedback(
    s: URSample, *, moving: bool, current_command_id: int, estop_latched: bool = False
) -> FeedbackState:
    mode = dobot_mode(s, moving, estop_latched)
    return FeedbackState(
        q=np.array(s.q, dtype=float),
        qd=np.array(s.qd, dtype=float),
        q_target=np.array(s.q_target, dtype=float),
        T_base_tool=pose_to_transform(s.tcp_pose),
        tcp_force=np.array(s.tcp_force, dtype=float),
        robot_mode=int(mode),
        current_command_id=current_command_id,
        digital_inputs=int(s.digital_inputs),
        digital_outputs=int(s.digital_outputs),
        enabled=mode in (RobotMode.ENABLE, RobotMode.RUNNING),
        error=mode is RobotMode.ERROR,
        collision=False,
        running=mode is RobotMode.RUNNING,
        estop=s.estop or estop_latched,
        timestamp_ms=round(s.timestamp_s * 1000.0),
        received_ns=s.received_ns,
    )


def _name(enum_cls: type[SafetyMode] | type[URRobotMode], value: int) -> str:
    try:
        return enum_cls(value).name
    except ValueError:
        return f"UNKNOWN({value})"


def describe(s: URSample) -> str:
    """The controller's state in its own words (a UR reports causes on its pendant, not over RTDE)."""
    return (
        f"UR safety mode {_name(SafetyMode, s.safety_mode)}, robot mode {_name(URRobotMode, s.robot_mode)}, "
        f"program {'running' if s.program_running else 'not running'}"
    )
