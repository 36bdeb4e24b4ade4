"""The simulated Nova5 controller: protocol semantics without I/O.

``handle(text)`` answers one dashboard command exactly as the V4 controller
would (``ErrorID,{values},Cmd;``); ``tick(dt)`` advances the queue, the joint
reference and the motion engine by ``dt`` seconds of sim time and refreshes the
1440-byte feedback record. The TCP server (``dobot_server``) owns the sockets
and the clock. Follows the simulator checklist of the protocol spec (§8).
"""

from __future__ import annotations

import collections
import enum
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from services import dobot
from services.common.errors import IKFailureError
from services.common.frames import transform_to_dobot_pose
from services.dobot import RobotMode
from services.kinematics import analytic
from services.kinematics.cartesian import straight_line_joint_path
from services.kinematics.robot_models import RobotSpec
from services.sim.command_args import CommandError
from services.sim.dashboard_commands import HANDLERS
from services.sim.engine import EngineState, MotionEngine
from services.sim.motion_profiles import PathProfile, PointToPoint, Profile, trapezoid_time

log = logging.getLogger("pickplace.sim.controller")

MAX_TCP_SPEED_MM_S = 1000.0
MAX_TCP_ACC_MM_S2 = 4000.0
COMMAND_LOG_KEPT = 1024
STOP_REST_RAD_S = 0.002  # a stopping arm is at rest (and held where it is) below this on every joint


@dataclass
class QueuedCommand:
    id: int
    key: str
    run: Callable[[], Profile | None]  # start the command; returns a motion profile or None
    text: str = ""


@dataclass
class ControllerConfig:
    max_joint_speed_deg_s: float = 180.0
    max_joint_acc_deg_s2: float = 720.0
    error_id_shape: str = "v46"  # GetErrorID reply shape: "v46" ([ids]) or "v45" ([[c],[s1]..[s6]])
    robot_type: int = 103
    # ServoJ feed watchdog: a stream whose newest ServoJ arrived more than its ``t`` plus this margin
    # ago (sim time) is halted with its look-ahead dropped, as if the host had died. None = off: the
    # controller then ends a starved stream only when its queue runs dry (each ServoJ holds its target
    # once its t has run out), which is how a host that stops feeding at a trajectory's end must be
    # served unless it keeps feeding its final target until the arm is there.
    servo_watchdog_margin_s: float | None = None


class FaultKind(enum.Enum):
    """A tracking fault of the arm, injected to test the driver's execution monitoring."""

    LAG = "lag"  # every joint trails its reference (first-order, time constant ``lag_s``): a weak servo
    STUCK = "stuck"  # ``joint`` stops moving where it is (a blocked or braked joint)
    OFFSET = "offset"  # ``joint`` settles ``offset_rad`` away from its reference (a load, a slipped belt)


@dataclass(frozen=True)
class TrackingFault:
    kind: FaultKind
    joint: int = 0  # 0-based (STUCK)
    lag_s: float = 0.2  # (LAG)
    offset_rad: float = 0.0  # (OFFSET)


@dataclass
class _Ratios:
    speed_factor: int = 100
    acc_j: int = 100
    acc_l: int = 100
    vel_j: int = 100
    vel_l: int = 100
    cp: int = 0


@dataclass
class _Motion:
    cmd: QueuedCommand
    profile: Profile
    t: float = 0.0


def _wall_ms() -> int:
    return int(time.time() * 1000)


class SimController:
    def __init__(
        self,
        spec: RobotSpec,
        engine: MotionEngine,
        config: ControllerConfig | None = None,
        q0: np.ndarray | None = None,
        clock_ms: Callable[[], int] = _wall_ms,  # read once: the epoch of the controller's clock
    ):
        self.spec = spec
        self.engine = engine
        self.config = config or ControllerConfig()
        self.mode_base = RobotMode.DISABLED  # mode without the alarm overlay
        self.enabled = False
        self.estop = False
        self.paused = False
        self.alarms: list[int] = []
        self.collision_state = False
        self.do_mask = 0
        self.tool_do_mask = 0
        self.ratios = _Ratios()
        self.queue: collections.deque[QueuedCommand] = collections.deque()
        self.next_id = 1
        self.current_cmd_id = 0
        self.motion: _Motion | None = None
        self.sim_time = 0.0
        self._servo_fed: tuple[float, float] | None = None  # (sim time of the newest ServoJ, its t)
        self.servo_watchdog_trips = 0
        self.servo_watchdog_tripped_ms: int | None = None  # the controller clock at the last trip
        self.tracking_fault: TrackingFault | None = None  # fault injection (tests): see TrackingFault
        self._stopping = False  # halted, the arm still braking: the reference follows it to rest
        q = np.zeros(spec.dof) if q0 is None else np.asarray(q0, dtype=float)
        self.q_ref = q.copy()
        self.qd_ref = np.zeros(spec.dof)
        self.qdd_ref = np.zeros(spec.dof)
        self.engine.reset(q)
        self.measured = EngineState(q=q.copy(), qd=np.zeros(spec.dof))
        # The controller's clock is sim time: TimeStamp = the wall clock at boot + the sim time since,
        # so every stamp agrees with the ticks that produced it whatever the machine's load or speed.
        self.boot_ms = clock_ms()
        self.commands_handled = 0
        # (controller clock ms, command text) of the newest commands: what arrived when, for tests
        self.command_log: collections.deque[tuple[int, str]] = collections.deque(maxlen=COMMAND_LOG_KEPT)
        self._feedback = dobot.new_feedback()
        self._refresh_feedback()

    # ------------------------------------------------------------------ state
    @property
    def mode(self) -> RobotMode:
        if self.alarms:
            if self.collision_state:
                return RobotMode.COLLISION
            return RobotMode.ERROR
        if not self.enabled:
            return RobotMode.DISABLED
        if self.paused:
            return RobotMode.PAUSE
        if self.motion is not None or self.queue:
            return RobotMode.RUNNING
        return RobotMode.ENABLE

    def raise_alarm(self, alarm_id: int, why: str) -> None:
        if alarm_id not in self.alarms:
            self.alarms.append(alarm_id)
        log.warning("alarm %d (%s): %s", alarm_id, dobot.describe_alarm(alarm_id), why)
        self.halt()

    def halt(self) -> None:
        """Stop motion immediately and drop the queue (alarm, e-stop, Stop)."""
        self.queue.clear()
        if self.motion is not None:
            self.current_cmd_id = self.motion.cmd.id
        self.motion = None
        self.q_ref = self.measured.q.copy()
        self.qd_ref = np.zeros(self.spec.dof)
        self.qdd_ref = np.zeros(self.spec.dof)
        self.engine.hold()
        self._stopping = True

    # ------------------------------------------------------------------ clock
    @property
    def clock_ms(self) -> int:
        """The controller's clock (ms): boot time + sim time, never the wall clock after boot."""
        return self.boot_ms + round(self.sim_time * 1000.0)

    def tick(self, dt: float) -> None:
        """Advance sim time by dt: queue, reference, engine, alarms, feedback record."""
        self.sim_time += dt
        self._servo_watchdog()
        if self._stopping:
            # a stop brakes the arm and holds it where it comes to rest, as a drive's quick stop does
            # (holding the pose of the stop's instant pulled the arm back over its stopping distance:
            # 152 ms before it was at rest from 0.63 rad/s in the twin, instead of 56 ms)
            self.q_ref = self.measured.q.copy()
        if self.enabled and not self.alarms and not self.paused:
            remaining = dt
            while remaining > 0:
                if self.motion is None:
                    if not self._start_next():
                        break
                    continue
                m = self.motion
                step = min(remaining, max(m.profile.duration - m.t, 0.0))
                m.t += step
                remaining -= step
                self.q_ref, self.qd_ref, self.qdd_ref = m.profile.sample(m.t)
                if m.t >= m.profile.duration - 1e-12:
                    self.q_ref, _, _ = m.profile.sample(m.profile.duration)
                    self.qd_ref = np.zeros(self.spec.dof)
                    self.qdd_ref = np.zeros(self.spec.dof)
                    self.motion = None
                    if step == 0 and remaining > 0:
                        continue
                if step == 0:
                    break
        else:
            self.qd_ref = np.zeros(self.spec.dof)
            self.qdd_ref = np.zeros(self.spec.dof)
        before = self.measured
        self.measured = self.engine.step(dt, self.q_ref, self.qd_ref, self.qdd_ref)
        if self._stopping and (
            self.motion is not None or float(np.max(np.abs(self.measured.qd))) < STOP_REST_RAD_S
        ):
            self._stopping = False  # at rest (held here from now on), or a new motion took over
        if self.tracking_fault is not None:
            self.measured = _with_fault(self.tracking_fault, before, self.measured, dt)
        self._check_measured()
        self._refresh_feedback()

    def servo_fed(self, t_s: float) -> None:
        """A ServoJ arrived (its ``t``): the stream is fed until ``t`` plus the margin from now."""
        self._servo_fed = (self.sim_time, t_s)

    def _servo_stream_active(self) -> bool:
        running = self.motion is not None and self.motion.cmd.key == "servoj"
        return running or any(c.key == "servoj" for c in self.queue)

    def _servo_watchdog(self) -> None:
        margin = self.config.servo_watchdog_margin_s
        if self._servo_fed is None:
            return
        if not self._servo_stream_active():
            self._servo_fed = None  # the stream ended (ran dry, or was stopped)
            return
        fed_at, t_s = self._servo_fed
        if margin is not None and self.sim_time - fed_at > t_s + margin:
            self.servo_watchdog_trips += 1
            log.warning(
                "ServoJ stream not fed for %.3fs (t=%.3fs + %.3fs margin): halted, %d queued targets dropped",
                self.sim_time - fed_at,
                t_s,
                margin,
                len(self.queue),
            )
            self._servo_fed = None
            self.servo_watchdog_tripped_ms = self.clock_ms
            self.halt()

    def _start_next(self) -> bool:
        if not self.queue:
            return False
        cmd = self.queue.popleft()
        self.current_cmd_id = cmd.id
        try:
            profile = cmd.run()
        except CommandError as exc:  # an alarm raised while starting
            log.debug("queued %s failed to start: %s", cmd.key, exc)
            return False
        if profile is not None and profile.duration > 0:
            self.motion = _Motion(cmd, profile)
        return True

    def _check_measured(self) -> None:
        if self.measured.collision and 117 not in self.alarms:
            self.collision_state = True
            self.raise_alarm(int(dobot.Alarm.COLLISION), self.measured.collision)
        hit = self._limit_violation(self.measured.q, 1e-3)
        if hit is not None and hit[0] not in self.alarms:
            self.raise_alarm(*hit)

    def _limit_violation(self, q: np.ndarray, tol: float) -> tuple[int, str] | None:
        """(alarm id, description) of the first joint outside its limits, or None."""
        for j in range(self.spec.dof):
            for positive, beyond in (
                (True, q[j] > self.spec.upper[j] + tol),
                (False, q[j] < self.spec.lower[j] - tol),
            ):
                if beyond:
                    return dobot.joint_limit_alarm(j, positive), f"joint {j + 1} at {np.rad2deg(q[j]):.2f}°"
        return None

    # ------------------------------------------------------------------ feedback
    def _refresh_feedback(self) -> None:
        rec = self._feedback
        q_deg = np.rad2deg(self.measured.q)
        rec["RunTime"] = self.clock_ms - self.boot_ms
        rec["TimeStamp"] = self.clock_ms
        rec["RobotMode"] = int(self.mode)
        rec["DigitalOutputs"] = self.do_mask
        rec["DigitalInputs"] = self.measured.digital_inputs
        rec["SpeedScaling"] = float(self.ratios.speed_factor)
        rec["VRobot"] = 48.0
        rec["QTarget"] = np.rad2deg(self.q_ref)
        rec["QDTarget"] = np.rad2deg(self.qd_ref)
        rec["QDDTarget"] = np.rad2deg(self.qdd_ref)
        rec["QActual"] = q_deg
        rec["QDActual"] = np.rad2deg(self.measured.qd)
        rec["MActual"] = self.measured.effort
        rec["ActualTCPForce"] = self.measured.tcp_force
        rec["SixForceValue"] = self.measured.tcp_force
        rec["TCPForce"] = self.measured.tcp_force
        rec["ToolVectorActual"] = transform_to_dobot_pose(analytic.fk(self.spec, self.measured.q))
        rec["ToolVectorTarget"] = transform_to_dobot_pose(analytic.fk(self.spec, self.q_ref))
        rec["MotorTemperatures"] = 35.0
        rec["JointModes"] = 8.0
        rec["VelocityRatio"] = min(self.ratios.vel_j, 100)
        rec["AccelerationRatio"] = min(self.ratios.acc_j, 100)
        rec["EnableStatus"] = 1 if self.enabled else 0
        rec["RunningStatus"] = 1 if self.motion is not None else 0
        rec["ErrorStatus"] = 1 if self.alarms else 0
        rec["CollisionState"] = 1 if self.collision_state else 0
        rec["CRRobotType"] = self.config.robot_type
        rec["CurrentCommandId"] = self.current_cmd_id
        rec["RunQueuedCmd"] = 1 if (self.motion is not None or self.queue) else 0
        rec["PauseCmdFlag"] = 1 if self.paused else 0
        # SafetyState is active-low: bit0 clear = e-stop
        rec["SafetyState"] = 0xFE if self.estop else 0xFF

    def feedback_bytes(self) -> bytes:
        return dobot.encode_feedback(self._feedback)

    # ------------------------------------------------------------------ commands
    def handle(self, text: str) -> str:
        """Answer one command (the text without surrounding whitespace)."""
        self.commands_handled += 1
        echo = text.strip()
        self.command_log.append((self.clock_ms, echo))
        try:
            cmd = dobot.parse_command(echo)
        except dobot.ProtocolError:
            name = echo.split("(", 1)[0].strip()
            if "(" in echo and name.lower() in HANDLERS:
                return dobot.format_reply(dobot.ErrorID.PARAM_COUNT, "", echo)
            return dobot.format_reply(dobot.ErrorID.UNKNOWN_COMMAND, "", echo)
        handler = HANDLERS.get(cmd.key)
        if handler is None:
            return dobot.format_reply(dobot.ErrorID.UNKNOWN_COMMAND, "", echo)
        try:
            self._gate(cmd.key)
            values = handler(self, cmd)
        except CommandError as exc:
            return dobot.format_reply(exc.error_id, "", echo)
        return dobot.format_reply(0, values, echo)

    def _gate(self, key: str) -> None:
        if key in dobot.ALLOWED_IN_ERROR:
            return
        if self.estop:
            raise CommandError(dobot.ErrorID.ESTOP)
        if self.alarms:
            raise CommandError(dobot.ErrorID.ALARM)

    def _joint_limits_deg(self) -> tuple[np.ndarray, np.ndarray]:
        return np.rad2deg(self.spec.lower), np.rad2deg(self.spec.upper)

    def _vmax(self, v: int) -> np.ndarray:
        scale = self.ratios.speed_factor / 100.0 * v / 100.0
        base = np.minimum(np.deg2rad(self.config.max_joint_speed_deg_s), self.spec.max_velocity)
        return base * max(scale, 1e-3)

    def _amax(self, a: int) -> np.ndarray:
        base = np.minimum(np.deg2rad(self.config.max_joint_acc_deg_s2), self.spec.max_acceleration)
        return base * max(a / 100.0, 1e-3)

    def enqueue(self, key: str, run: Callable[[], Profile | None], text: str) -> list[object]:
        if not self.enabled:
            raise CommandError(dobot.ErrorID.FAILED)
        cid = self.next_id
        self.next_id += 1
        self.queue.append(QueuedCommand(cid, key, run, text))
        return [cid]

    def _queue_tail_q(self) -> np.ndarray:
        return self.q_ref.copy()

    # --- motion starters (run when the command reaches the head of the queue)
    def check_target_limits(self, q: np.ndarray) -> None:
        hit = self._limit_violation(q, 1e-9)
        if hit is not None:
            self.raise_alarm(hit[0], "target " + hit[1])
            raise CommandError(dobot.ErrorID.ALARM)

    def ik_or_alarm(self, T: np.ndarray, seed: np.ndarray) -> np.ndarray:
        sols = analytic.solutions_within_limits(self.spec, T, seed)
        if sols.shape[0] == 0:
            _, valid = analytic.ik_all(self.spec, T)
            alarm = dobot.Alarm.IK_OUT_OF_WORKSPACE if valid.any() else dobot.Alarm.IK_NO_SOLUTION
            self.raise_alarm(int(alarm), f"pose {np.round(transform_to_dobot_pose(T), 3).tolist()}")
            raise CommandError(dobot.ErrorID.ALARM)
        q = sols[0]
        if analytic.manipulability(self.spec, q) < 1e-4:
            self.raise_alarm(int(dobot.Alarm.WRIST_SINGULARITY), "target is at a singularity")
            raise CommandError(dobot.ErrorID.ALARM)
        return q

    def movj_to(self, q_goal: np.ndarray, a: int, v: int) -> Profile:
        self.check_target_limits(q_goal)
        return PointToPoint(self.q_ref, q_goal, self._vmax(v), self._amax(a))

    def movl_to(
        self,
        T_goal: np.ndarray,
        a: int,
        v: int,
        speed_mm_s: float | None,
        q_goal_hint: np.ndarray | None = None,
    ) -> Profile:
        T_start = analytic.fk(self.spec, self.q_ref)
        try:
            path = straight_line_joint_path(self.spec, T_start, T_goal, self.q_ref)
        except IKFailureError as exc:
            msg = str(exc)
            alarm = dobot.Alarm.WRIST_SINGULARITY if "jump" in msg else dobot.Alarm.IK_NO_SOLUTION
            self.raise_alarm(int(alarm), f"MovL: {msg}")
            raise CommandError(dobot.ErrorID.ALARM) from None
        if q_goal_hint is not None and np.max(np.abs(path[-1] - q_goal_hint)) > 1e-3:
            self.raise_alarm(int(dobot.Alarm.IK_NO_SOLUTION), "MovL cannot reach the joint target on a line")
            raise CommandError(dobot.ErrorID.ALARM)
        for q in path:
            self.check_target_limits(q)
        length_mm = np.linalg.norm(T_goal[:3, 3] - T_start[:3, 3]) * 1000.0
        scale = self.ratios.speed_factor / 100.0 * v / 100.0
        tcp_speed = speed_mm_s if speed_mm_s is not None else MAX_TCP_SPEED_MM_S * max(scale, 1e-3)
        tcp_acc = MAX_TCP_ACC_MM_S2 * max(a / 100.0, 1e-3)
        floor = 0.0
        if length_mm > 0:
            floor = trapezoid_time(float(length_mm), tcp_speed, tcp_acc)
        return PathProfile(path, floor, self._vmax(v), self._amax(a))

    def set_do(self, index: int, on: bool, tool: bool) -> None:
        bit = 1 << (index - 1)
        if tool:
            self.tool_do_mask = (self.tool_do_mask | bit) if on else (self.tool_do_mask & ~bit)
        else:
            self.do_mask = (self.do_mask | bit) if on else (self.do_mask & ~bit)
        # the engine sees cabinet DOs in bits 0..31 and flange ToolDOs in bits 32..
        self.engine.set_digital_outputs(self.do_mask | (self.tool_do_mask << 32))


def _with_fault(fault: TrackingFault, before: EngineState, now: EngineState, dt: float) -> EngineState:
    """What the encoders read under ``fault``: the engine's state bent by it (the reference unchanged)."""
    q = now.q.copy()
    if fault.kind is FaultKind.LAG:
        q = before.q + (now.q - before.q) * min(1.0, dt / max(fault.lag_s, dt))
    elif fault.kind is FaultKind.STUCK:
        q[fault.joint] = before.q[fault.joint]
    elif fault.kind is FaultKind.OFFSET:
        q[fault.joint] += fault.offset_rad
    qd = (q - before.q) / dt if dt > 0 else np.zeros_like(q)
    return replace(now, q=q, qd=qd)
