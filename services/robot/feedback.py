"""What the Dobot client reports: the feedback state of one packet (SI units) and the link's state and
events. Plain types (no I/O), shared by the client, the driver and its supervision."""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from services import dobot
from services.common.frames import dobot_pose_to_transform
from services.dobot import RobotMode


class LinkState(enum.Enum):
    """The controller link as the feedback stream sees it (health reports anything but UP as down)."""

    DOWN = "down"  # not yet connected, or closed
    UP = "up"  # sound packets arriving
    RECONNECTING = "reconnecting"  # lost; retrying for as long as the client lives


class LinkEventKind(enum.Enum):
    LOST = "lost"
    RESTORED = "restored"
    STOP_SENT = "stop sent"


@dataclass(frozen=True)
class LinkEvent:
    """One change of the link, stamped on the controller's clock: a loss with the last sound packet's
    stamp before it, a restore with the first one after it, a Stop with the newest stamp when the
    controller accepted it."""

    kind: LinkEventKind
    epoch: int  # the link epoch after the event (each loss starts a new one)
    stamp_ms: int | None
    reason: str


# no joint turning faster than this: the arm is at rest (a stopped or starved arm still brakes, and a
# physical one settles behind its reference, for a moment)
REST_SPEED_RAD_S = 0.01


class ClientState(enum.Enum):
    IDLE = "idle"
    CONNECTING = "connecting"
    CONNECTED = "connected"
    DISCONNECTED = "disconnected"
    CLOSED = "closed"


@dataclass(frozen=True)
class FeedbackState:
    """One decoded feedback packet, in SI units."""

    q: np.ndarray  # rad
    qd: np.ndarray  # rad/s
    q_target: np.ndarray  # rad
    T_base_tool: np.ndarray  # 4x4, m (ToolVectorActual)
    tcp_force: np.ndarray  # N, N·m
    robot_mode: int
    current_command_id: int
    digital_inputs: int
    digital_outputs: int
    enabled: bool
    error: bool
    collision: bool
    running: bool
    estop: bool
    timestamp_ms: int  # controller clock
    received_ns: int  # local time.time_ns() at receipt

    @classmethod
    def from_record(
        cls, rec: np.ndarray, received_ns: int, prev_stamp_ms: int | None = None
    ) -> FeedbackState:
        """The state of one packet; ProtocolError when a value the driver uses is not finite or not
        plausible, or the controller clock ran backwards from ``prev_stamp_ms``."""
        fault = dobot.feedback_fault(rec, prev_stamp_ms)
        if fault is not None:
            raise dobot.ProtocolError(f"bad feedback packet: {fault}")
        return cls(
            q=np.deg2rad(np.array(rec["QActual"], dtype=float)),
            qd=np.deg2rad(np.array(rec["QDActual"], dtype=float)),
            q_target=np.deg2rad(np.array(rec["QTarget"], dtype=float)),
            T_base_tool=dobot_pose_to_transform(np.array(rec["ToolVectorActual"], dtype=float)),
            tcp_force=np.array(rec["ActualTCPForce"], dtype=float),
            robot_mode=int(rec["RobotMode"]),
            current_command_id=int(rec["CurrentCommandId"]),
            digital_inputs=int(rec["DigitalInputs"]),
            digital_outputs=int(rec["DigitalOutputs"]),
            enabled=bool(rec["EnableStatus"]),
            error=bool(rec["ErrorStatus"]),
            collision=bool(rec["CollisionState"]),
            running=bool(rec["RunningStatus"]),
            estop=not (int(rec["SafetyState"]) & 0x01),
            timestamp_ms=int(rec["TimeStamp"]),
            received_ns=received_ns,
        )

    @property
    def at_rest(self) -> bool:
        return float(np.max(np.abs(self.qd))) < REST_SPEED_RAD_S

    @property
    def in_error(self) -> bool:
        return self.robot_mode in (RobotMode.ERROR, RobotMode.COLLISION)
