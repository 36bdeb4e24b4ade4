"""The simulated Nova5 controller: protocol semantics without I/O.

``handle(text)`` answers one dashboard command exactly as the V4 controller
would (``ErrorID,{values},Cmd;``); ``tick(dt)`` advances the queue, the joint
reference and the motion engine by ``dt`` seconds of sim time and refreshes the
1440-byte feedback record. The TCP server (``dobot_server``) owns the sockets
and the clock. Follows the simulator checklist of the protocol spec (§8).
"""

from __future__ import annotations

import collections
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from services import dobot
from services.common.errors import IKFailureError
from services.common.frames import (
    dobot_pose_to_transform,
    make_transform,
    rpy_deg_to_matrix,
    transform_to_dobot_pose,
)
from services.dobot import RobotMode
from services.kinematics import analytic
from services.kinematics.cartesian import straight_line_joint_path
from services.kinematics.robot_models import RobotSpec
from services.sim.engine import EngineState, MotionEngine
from services.sim.motion_profiles import LinearInTime, PathProfile, PointToPoint, Profile, trapezoid_time

log = logging.getLogger("pickplace.sim.controller")

PARAM_LIMIT_DEG = 360.0  # a joint value beyond ±360° is a parameter range error (-4000X)
MAX_TCP_SPEED_MM_S = 1000.0
MAX_TCP_ACC_MM_S2 = 4000.0


Handler = Callable[["SimController", dobot.ParsedCommand], object]


class CommandError(Exception):
    """A command is refused with a protocol ErrorID."""

    def __init__(self, error_id: int):
        super().__init__(error_id)
        self.error_id = error_id


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
        clock_ms: Callable[[], int] = _wall_ms,
    ):
        self.spec = spec
        self.engine = engine
        self.config = config or ControllerConfig()
        self._clock_ms = clock_ms
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
        q = np.zeros(spec.dof) if q0 is None else np.asarray(q0, dtype=float)
        self.q_ref = q.copy()
        self.qd_ref = np.zeros(spec.dof)
        self.qdd_ref = np.zeros(spec.dof)
        self.engine.reset(q)
        self.measured = EngineState(q=q.copy(), qd=np.zeros(spec.dof))
        self.boot_ms = clock_ms()
        self.commands_handled = 0
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
        self._halt()

    def _halt(self) -> None:
        """Stop motion immediately and drop the queue (alarm, e-stop, Stop)."""
        self.queue.clear()
        if self.motion is not None:
            self.current_cmd_id = self.motion.cmd.id
        self.motion = None
        self.q_ref = self.measured.q.copy()
        self.qd_ref = np.zeros(self.spec.dof)
        self.qdd_ref = np.zeros(self.spec.dof)
        self.engine.hold()

    # ------------------------------------------------------------------ clock
    def tick(self, dt: float) -> None:
        """Advance sim time by dt: queue, reference, engine, alarms, feedback record."""
        self.sim_time += dt
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
        self.measured = self.engine.step(dt, self.q_ref, self.qd_ref, self.qdd_ref)
        self._check_measured()
        self._refresh_feedback()

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
        rec["TimeStamp"] = self._clock_ms()
        rec["RunTime"] = max(0, self._clock_ms() - self.boot_ms)
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
        try:
            cmd = dobot.parse_command(echo)
        except dobot.ProtocolError:
            name = echo.split("(", 1)[0].strip()
            if "(" in echo and name.lower() in self._handlers:
                return dobot.format_reply(dobot.ErrorID.PARAM_COUNT, "", echo)
            return dobot.format_reply(dobot.ErrorID.UNKNOWN_COMMAND, "", echo)
        handler = self._handlers.get(cmd.key)
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

    # --- argument helpers
    @staticmethod
    def _nargs(cmd: dobot.ParsedCommand, lo: int, hi: int | None = None) -> None:
        hi = lo if hi is None else hi
        if not lo <= len(cmd.args) <= hi:
            raise CommandError(dobot.ErrorID.PARAM_COUNT)

    @staticmethod
    def _float(text: str, pos: int, optional: bool = False) -> float:
        try:
            v = float(text)
        except ValueError:
            raise CommandError((-50000 if optional else -30000) - pos) from None
        if not np.isfinite(v):
            raise CommandError((-60000 if optional else -40000) - pos)
        return v

    def _int(self, text: str, pos: int, lo: int, hi: int, optional: bool = False) -> int:
        v = self._float(text, pos, optional)
        if v != int(v):
            raise CommandError((-50000 if optional else -30000) - pos)
        if not lo <= v <= hi:
            raise CommandError((-60000 if optional else -40000) - pos)
        return int(v)

    def _opt_ratio(self, cmd: dobot.ParsedCommand, key: str, default: int, lo: int = 1) -> int:
        if key not in cmd.kwargs:
            return default
        return self._int(cmd.kwargs[key], 1, lo, 100, optional=True)

    def _point(self, text: str, pos: int) -> np.ndarray:
        try:
            pts = dobot.parse_point(text, 6)
        except ValueError:
            raise CommandError(-30000 - pos) from None
        arr = np.array(pts)
        if not np.all(np.isfinite(arr)):
            raise CommandError(-40000 - pos)
        return arr

    def _joint_or_pose(self, cmd: dobot.ParsedCommand) -> tuple[str, np.ndarray]:
        """MovJ/MovL target: ``joint={..}`` or ``pose={..}`` (or six positional pose values)."""
        if "joint" in cmd.kwargs:
            if cmd.args:
                raise CommandError(dobot.ErrorID.PARAM_COUNT)
            q_deg = self._point(cmd.kwargs["joint"], 1)
            if np.any(np.abs(q_deg) > PARAM_LIMIT_DEG):
                raise CommandError(-40001)
            return "joint", q_deg
        if "pose" in cmd.kwargs:
            if cmd.args:
                raise CommandError(dobot.ErrorID.PARAM_COUNT)
            return "pose", self._point(cmd.kwargs["pose"], 1)
        if len(cmd.args) == 6:
            return "pose", np.array([self._float(a, i + 1) for i, a in enumerate(cmd.args)])
        raise CommandError(dobot.ErrorID.PARAM_COUNT)

    def _joint_limits_deg(self) -> tuple[np.ndarray, np.ndarray]:
        return np.rad2deg(self.spec.lower), np.rad2deg(self.spec.upper)

    def _vmax(self, v: int) -> np.ndarray:
        scale = self.ratios.speed_factor / 100.0 * v / 100.0
        base = np.minimum(np.deg2rad(self.config.max_joint_speed_deg_s), self.spec.max_velocity)
        return base * max(scale, 1e-3)

    def _amax(self, a: int) -> np.ndarray:
        base = np.minimum(np.deg2rad(self.config.max_joint_acc_deg_s2), self.spec.max_acceleration)
        return base * max(a / 100.0, 1e-3)

    def _enqueue(self, key: str, run: Callable[[], Profile | None], text: str) -> list[int]:
        if not self.enabled:
            raise CommandError(dobot.ErrorID.FAILED)
        cid = self.next_id
        self.next_id += 1
        self.queue.append(QueuedCommand(cid, key, run, text))
        return [cid]

    def _queue_tail_q(self) -> np.ndarray:
        return self.q_ref.copy()

    # --- motion starters (run when the command reaches the head of the queue)
    def _check_target_limits(self, q: np.ndarray) -> None:
        hit = self._limit_violation(q, 1e-9)
        if hit is not None:
            self.raise_alarm(hit[0], "target " + hit[1])
            raise CommandError(dobot.ErrorID.ALARM)

    def _ik_or_alarm(self, T: np.ndarray, seed: np.ndarray) -> np.ndarray:
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

    def _movj_to(self, q_goal: np.ndarray, a: int, v: int) -> Profile:
        self._check_target_limits(q_goal)
        return PointToPoint(self.q_ref, q_goal, self._vmax(v), self._amax(a))

    def _movl_to(
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
            self._check_target_limits(q)
        length_mm = np.linalg.norm(T_goal[:3, 3] - T_start[:3, 3]) * 1000.0
        scale = self.ratios.speed_factor / 100.0 * v / 100.0
        tcp_speed = speed_mm_s if speed_mm_s is not None else MAX_TCP_SPEED_MM_S * max(scale, 1e-3)
        tcp_acc = MAX_TCP_ACC_MM_S2 * max(a / 100.0, 1e-3)
        floor = 0.0
        if length_mm > 0:
            floor = trapezoid_time(length_mm, tcp_speed, tcp_acc)
        return PathProfile(path, floor, self._vmax(v), self._amax(a))

    # --- handlers
    def _h_enable(self, cmd: dobot.ParsedCommand) -> list[object]:
        if len(cmd.args) not in (0, 1, 4, 5):
            raise CommandError(dobot.ErrorID.PARAM_COUNT)
        if cmd.args:
            load = self._float(cmd.args[0], 1)
            if not 0 <= load <= 5:
                raise CommandError(-40001)
        self.enabled = True
        self.engine.hold()
        return []

    def _h_disable(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        self._halt()
        self.enabled = False
        return []

    def _h_clear_error(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        if self.estop:
            raise CommandError(dobot.ErrorID.ESTOP)
        self.alarms.clear()
        self.collision_state = False
        self.q_ref = self.measured.q.copy()
        return []

    def _h_robot_mode(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        return [int(self.mode)]

    def _h_get_error_id(self, cmd: dobot.ParsedCommand) -> str:
        self._nargs(cmd, 0)
        ids = ",".join(str(a) for a in self.alarms)
        if self.config.error_id_shape == "v45":
            return f"[[{ids}],[],[],[],[],[],[]]"
        return f"[{ids}]"

    def _h_stop(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        self._halt()
        self.paused = False
        return []

    def _h_pause(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        self.paused = True
        return []

    def _h_continue(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        self.paused = False
        return []

    def _h_estop(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0, 1)
        press = True if not cmd.args else bool(self._int(cmd.args[0], 1, 0, 1))
        if press:
            self.estop = True
            self.enabled = False
            self.raise_alarm(int(dobot.Alarm.ESTOP_PRESSED), "software emergency stop")
        else:
            self.estop = False
        return []

    def _h_speed_factor(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 1)
        self.ratios.speed_factor = self._int(cmd.args[0], 1, 1, 100)
        return []

    @staticmethod
    def _h_ratio(attr: str, lo: int = 1) -> Handler:
        def h(self: SimController, cmd: dobot.ParsedCommand) -> list[object]:
            self._nargs(cmd, 1)
            setattr(self.ratios, attr, self._int(cmd.args[0], 1, lo, 100))
            return []

        return h

    def _h_get_angle(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        return [float(x) for x in np.rad2deg(self.measured.q)]

    def _h_get_pose(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        if ("user" in cmd.kwargs) != ("tool" in cmd.kwargs):
            raise CommandError(-50001)
        return [float(x) for x in transform_to_dobot_pose(analytic.fk(self.spec, self.measured.q))]

    def _h_positive_kin(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 6)
        q_deg = np.array([self._float(a, i + 1) for i, a in enumerate(cmd.args)])
        return [float(x) for x in transform_to_dobot_pose(analytic.fk(self.spec, np.deg2rad(q_deg)))]

    def _h_inverse_kin(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 6)
        pose = np.array([self._float(a, i + 1) for i, a in enumerate(cmd.args)])
        seed = self.measured.q
        if cmd.kwargs.get("usejointnear", "0").strip() == "1" and "jointnear" in cmd.kwargs:
            seed = np.deg2rad(self._point(cmd.kwargs["jointnear"], 1))
        sols = analytic.solutions_within_limits(self.spec, dobot_pose_to_transform(pose), seed)
        if sols.shape[0] == 0:
            raise CommandError(dobot.ErrorID.FAILED)
        return [float(x) for x in np.rad2deg(sols[0])]

    def _h_current_id(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 0)
        return [self.current_cmd_id]

    def _h_movj(self, cmd: dobot.ParsedCommand) -> list[object]:
        kind, target = self._joint_or_pose(cmd)
        a = self._opt_ratio(cmd, "a", self.ratios.acc_j)
        v = self._opt_ratio(cmd, "v", self.ratios.vel_j)
        self._opt_ratio(cmd, "cp", self.ratios.cp, lo=0)

        def run() -> Profile:
            if kind == "joint":
                q_goal = np.deg2rad(target)
            else:
                q_goal = self._ik_or_alarm(dobot_pose_to_transform(target), self.q_ref)
            return self._movj_to(q_goal, a, v)

        return self._enqueue("movj", run, cmd.raw)

    def _h_movl(self, cmd: dobot.ParsedCommand) -> list[object]:
        kind, target = self._joint_or_pose(cmd)
        a = self._opt_ratio(cmd, "a", self.ratios.acc_l)
        v = self._opt_ratio(cmd, "v", self.ratios.vel_l)
        speed = None
        if "speed" in cmd.kwargs:
            speed = float(self._int(cmd.kwargs["speed"], 1, 1, 10000, optional=True))

        def run() -> Profile:
            if kind == "joint":
                q_goal = np.deg2rad(target)
                self._check_target_limits(q_goal)
                return self._movl_to(analytic.fk(self.spec, q_goal), a, v, speed, q_goal_hint=q_goal)
            return self._movl_to(dobot_pose_to_transform(target), a, v, speed)

        return self._enqueue("movl", run, cmd.raw)

    def _h_servoj(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 6)
        q_deg = np.array([self._float(a, i + 1) for i, a in enumerate(cmd.args)])
        if np.any(np.abs(q_deg) > PARAM_LIMIT_DEG):
            raise CommandError(-40001)
        t = 0.1
        if "t" in cmd.kwargs:
            t = self._float(cmd.kwargs["t"], 1, optional=True)
            if not 0.004 <= t <= 3600:
                raise CommandError(-60001)
        q_goal = np.deg2rad(q_deg)

        def run() -> Profile:
            self._check_target_limits(q_goal)
            speed = np.abs(q_goal - self.q_ref) / t
            over = np.nonzero(speed > self.spec.max_velocity * 1.05)[0]
            if over.size:
                j = int(over[0])
                self.raise_alarm(
                    dobot.joint_overspeed_alarm(j),
                    f"ServoJ asks joint {j + 1} for {np.rad2deg(speed[j]):.1f}°/s",
                )
                raise CommandError(dobot.ErrorID.ALARM)
            return LinearInTime(self.q_ref, q_goal, t)

        return self._enqueue("servoj", run, cmd.raw)

    def _h_rel_joint(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 6)
        d = np.deg2rad([self._float(x, i + 1) for i, x in enumerate(cmd.args)])
        a = self._opt_ratio(cmd, "a", self.ratios.acc_j)
        v = self._opt_ratio(cmd, "v", self.ratios.vel_j)
        return self._enqueue("reljointmovj", lambda: self._movj_to(self.q_ref + d, a, v), cmd.raw)

    @staticmethod
    def _h_rel_cartesian(frame: str, linear: bool) -> Handler:
        def h(self: SimController, cmd: dobot.ParsedCommand) -> list[object]:
            self._nargs(cmd, 6)
            off = np.array([self._float(x, i + 1) for i, x in enumerate(cmd.args)])
            a = self._opt_ratio(cmd, "a", self.ratios.acc_l if linear else self.ratios.acc_j)
            v = self._opt_ratio(cmd, "v", self.ratios.vel_l if linear else self.ratios.vel_j)

            def run() -> Profile:
                T0 = analytic.fk(self.spec, self.q_ref)
                dT = make_transform(rpy_deg_to_matrix(off[3:]), off[:3] / 1000.0)
                if frame == "tool":
                    T1 = T0 @ dT
                else:  # user frame = base: translate, rotate about the base axes at the TCP
                    T1 = T0.copy()
                    T1[:3, 3] = T0[:3, 3] + dT[:3, 3]
                    T1[:3, :3] = dT[:3, :3] @ T0[:3, :3]
                if linear:
                    return self._movl_to(T1, a, v, None)
                return self._movj_to(self._ik_or_alarm(T1, self.q_ref), a, v)

            return self._enqueue(cmd.key, run, cmd.raw)

        return h

    def _set_do(self, index: int, on: bool, tool: bool) -> None:
        bit = 1 << (index - 1)
        if tool:
            self.tool_do_mask = (self.tool_do_mask | bit) if on else (self.tool_do_mask & ~bit)
        else:
            self.do_mask = (self.do_mask | bit) if on else (self.do_mask & ~bit)
        # the engine sees cabinet DOs in bits 0..31 and flange ToolDOs in bits 32..
        self.engine.set_digital_outputs(self.do_mask | (self.tool_do_mask << 32))

    @staticmethod
    def _h_do(tool: bool, instant: bool) -> Handler:
        def h(self: SimController, cmd: dobot.ParsedCommand) -> list[object]:
            self._nargs(cmd, 2, 3 if not instant and not tool else 2)
            index = self._int(cmd.args[0], 1, 1, 2 if tool else 64)
            on = bool(self._int(cmd.args[1], 2, 0, 1))
            if instant:
                self._set_do(index, on, tool)
                return []

            def run() -> Profile | None:
                self._set_do(index, on, tool)
                return None

            return self._enqueue(cmd.key, run, cmd.raw)

        return h

    @staticmethod
    def _h_get_do(tool: bool) -> Handler:
        def h(self: SimController, cmd: dobot.ParsedCommand) -> list[object]:
            self._nargs(cmd, 1)
            index = self._int(cmd.args[0], 1, 1, 2 if tool else 64)
            mask = self.tool_do_mask if tool else self.do_mask
            return [(mask >> (index - 1)) & 1]

        return h

    def _h_di(self, cmd: dobot.ParsedCommand) -> list[object]:
        self._nargs(cmd, 1)
        index = self._int(cmd.args[0], 1, 1, 64)
        return [(self.measured.digital_inputs >> (index - 1)) & 1]

    @staticmethod
    def _h_noop(n: int) -> Handler:
        def h(self: SimController, cmd: dobot.ParsedCommand) -> list[object]:
            self._nargs(cmd, 0, n)
            return []

        return h

    @staticmethod
    def _h_queue_noop(lo: int, hi: int) -> Handler:
        def h(self: SimController, cmd: dobot.ParsedCommand) -> list[object]:
            self._nargs(cmd, lo, hi)
            return self._enqueue(cmd.key, lambda: None, cmd.raw)

        return h

    _handlers: ClassVar[dict[str, Handler]] = {}


SimController._handlers = {
    "enablerobot": SimController._h_enable,
    "disablerobot": SimController._h_disable,
    "clearerror": SimController._h_clear_error,
    "robotmode": SimController._h_robot_mode,
    "geterrorid": SimController._h_get_error_id,
    "stop": SimController._h_stop,
    "pause": SimController._h_pause,
    "continue": SimController._h_continue,
    "emergencystop": SimController._h_estop,
    "speedfactor": SimController._h_speed_factor,
    "accj": SimController._h_ratio("acc_j"),
    "accl": SimController._h_ratio("acc_l"),
    "velj": SimController._h_ratio("vel_j"),
    "vell": SimController._h_ratio("vel_l"),
    "cp": SimController._h_ratio("cp", 0),
    "getangle": SimController._h_get_angle,
    "getpose": SimController._h_get_pose,
    "positivekin": SimController._h_positive_kin,
    "inversekin": SimController._h_inverse_kin,
    "getcurrentcommandid": SimController._h_current_id,
    "movj": SimController._h_movj,
    "movl": SimController._h_movl,
    "servoj": SimController._h_servoj,
    "reljointmovj": SimController._h_rel_joint,
    "relmovjtool": SimController._h_rel_cartesian("tool", False),
    "relmovltool": SimController._h_rel_cartesian("tool", True),
    "relmovjuser": SimController._h_rel_cartesian("user", False),
    "relmovluser": SimController._h_rel_cartesian("user", True),
    "do": SimController._h_do(False, False),
    "doinstant": SimController._h_do(False, True),
    "tooldo": SimController._h_do(True, False),
    "tooldoinstant": SimController._h_do(True, True),
    "getdo": SimController._h_get_do(False),
    "gettooldo": SimController._h_get_do(True),
    "di": SimController._h_di,
    "tooldi": SimController._h_di,
    "poweron": SimController._h_noop(0),
    "requestcontrol": SimController._h_noop(0),
    "user": SimController._h_queue_noop(1, 1),
    "tool": SimController._h_queue_noop(1, 1),
    "setpayload": SimController._h_queue_noop(1, 4),
    "setcollisionlevel": SimController._h_queue_noop(1, 1),
}
