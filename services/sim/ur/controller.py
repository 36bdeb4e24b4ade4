"""The simulated UR controller's state machine (pure, controller time, no I/O).

One :meth:`URController.tick` is one 2 ms control cycle (500 Hz, the e-Series rate): the RTDE inputs
received since the last cycle are already in the registers; the program (ur_rtde's control script,
when one was sent to a script port) runs one cycle of its main loop; the arm's reference advances and
the engine tracks it; the outputs (``actual_q``, ``runtime_state``, the output registers…) are what
the next data package carries. Power, brakes, protective and emergency stops follow a real
controller's states (docs/ur/rtde.md §5); the dashboard (:mod:`services.sim.ur.dashboard`) and the
RTDE server (:mod:`services.sim.ur.server`) act on this object.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from services.kinematics import analytic
from services.kinematics.robot_models import RobotSpec
from services.rtde.codes import RobotStatusBit, RuntimeState, SafetyMode, SafetyStatusBit, URRobotMode
from services.rtde.fields import REGISTERS, register
from services.rtde.poses import transform_to_pose
from services.rtde.script import Program
from services.sim.engine import KinematicEngine, MotionEngine
from services.sim.ur.arm import ArmMotion, MotionFailure, SafetyViolation
from services.sim.ur.interpreter import ControlScript

log = logging.getLogger("pickplace.sim.ur")

TICK_S = 0.002  # the e-Series control cycle
CONTROLLER_VERSION = (5, 11, 1, 108318)
POLYSCOPE_VERSION = "URSoftware 5.11.1.108318 (Nov 03 2021)"
SERIAL_NUMBER = "20235500001"
ENGINE_TOOL_DO_SHIFT = 32  # services.sim.twin.engine.TOOL_DO_SHIFT (not imported: it pulls in MuJoCo)


@dataclass
class URControllerConfig:
    power_on_s: float = 0.5  # power on → IDLE (brakes still locked), controller time
    brake_release_s: float = 0.5  # brake release → RUNNING
    unlock_delay_s: float = 5.0  # a protective stop can be unlocked this long after it happened
    start_powered: bool = False  # boot straight into RUNNING (brakes released), for demos
    remote_control: bool = True  # what "is in remote control" answers
    q0: tuple[float, ...] = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class Event:
    """Something the controller logs (what a real one shows on the pendant)."""

    stamp_s: float
    text: str


class URController:
    def __init__(
        self, spec: RobotSpec, config: URControllerConfig | None = None, engine: MotionEngine | None = None
    ):
        self.spec = spec
        self.config = config or URControllerConfig()
        q0 = np.asarray(self.config.q0, dtype=float)
        self.engine: MotionEngine = engine or KinematicEngine(q0)
        self.engine.reset(q0)
        self.arm = ArmMotion(spec, q0)
        self.q = q0.copy()
        self.qd = np.zeros(spec.dof)
        self.tcp_force = np.zeros(6)  # N, N·m in the base frame
        self.timestamp_s = 0.0
        self.robot_mode = URRobotMode.RUNNING if self.config.start_powered else URRobotMode.POWER_OFF
        self.safety_mode = SafetyMode.NORMAL
        self.runtime_state = RuntimeState.STOPPED
        self._mode_change_at: float | None = None  # when a power-on / brake release completes
        self._mode_target: URRobotMode | None = None
        self.protective_stop_at: float | None = None
        self.estop = False
        self.in_int = [0] * REGISTERS
        self.register_writes = 0  # integer input register values received (a script's commands)
        self.in_double = [0.0] * REGISTERS
        self.out_int = [0] * REGISTERS
        self.out_double = [0.0] * REGISTERS
        self.standard_do = 0
        self.configurable_do = 0
        self.tool_do = 0
        self.digital_inputs = 0
        self.speed_slider = 1.0
        self.payload_kg = 0.0
        self.payload_cog = (0.0, 0.0, 0.0)
        self.program: Program | None = None
        self.script: ControlScript | None = None
        self.events: list[Event] = []
        self.ticks = 0
        self._pose_cache: dict[bytes, tuple[float, ...]] = {}

    # ------------------------------------------------------------------ log
    def note(self, text: str, level: int = logging.INFO) -> None:
        self.events.append(Event(self.timestamp_s, text))
        del self.events[:-200]
        log.log(level, "sim UR %s at %.3f s: %s", self.spec.name, self.timestamp_s, text)

    # ------------------------------------------------------------------ power (dashboard)
    def power_on(self) -> None:
        if self.robot_mode in (URRobotMode.POWER_OFF,) and not self.estop:
            self.robot_mode = URRobotMode.POWER_ON
            self._mode_target, self._mode_change_at = (
                URRobotMode.IDLE,
                self.timestamp_s + self.config.power_on_s,
            )

    def power_off(self) -> None:
        self.stop_program("power off")
        self._halt()
        self.robot_mode = URRobotMode.POWER_OFF
        self._mode_target = self._mode_change_at = None

    def brake_release(self) -> None:
        if self.robot_mode is URRobotMode.POWER_OFF:
            self.power_on()  # the pendant's "ON" then "START" in one: a real controller does the same
            assert self._mode_change_at is not None
            self._mode_target = URRobotMode.RUNNING
            self._mode_change_at += self.config.brake_release_s
        elif self.robot_mode in (URRobotMode.POWER_ON, URRobotMode.IDLE):
            self._mode_target = URRobotMode.RUNNING
            start = max(self.timestamp_s, self._mode_change_at or self.timestamp_s)
            self._mode_change_at = start + self.config.brake_release_s

    # ------------------------------------------------------------------ safety
    def _halt(self) -> None:
        """Standstill where the arm is (the measured joints: a twin's lag behind the reference)."""
        self.arm.halt()
        self.arm.ref.q = self.q.copy()
        self.engine.hold()

    def protective_stop(self, reason: str) -> None:
        self._halt()
        self.safety_mode = SafetyMode.PROTECTIVE_STOP
        self.protective_stop_at = self.timestamp_s
        self.note(f"Protective stop: {reason}", logging.WARNING)
        self.stop_program("protective stop")

    def unlock_protective_stop(self) -> str | None:
        """None when unlocked, else why not (in the dashboard's words)."""
        if self.safety_mode is not SafetyMode.PROTECTIVE_STOP:
            return None
        assert self.protective_stop_at is not None
        if self.timestamp_s - self.protective_stop_at < self.config.unlock_delay_s - 1e-9:
            return (
                f"Cannot unlock protective stop until {self.config.unlock_delay_s:g}s after occurrence. "
                "Always inspect cause of protective stop before unlocking"
            )
        self.safety_mode = SafetyMode.NORMAL
        self.protective_stop_at = None
        self.note("Protective stop released")
        return None

    def press_estop(self, pressed: bool = True) -> None:
        """The robot's emergency stop button (a hardware circuit: no protocol command presses it)."""
        if pressed and not self.estop:
            self.estop = True
            self.safety_mode = SafetyMode.ROBOT_EMERGENCY_STOP
            self.note("Emergency stop pressed")
            self.power_off()
        elif not pressed and self.estop:
            self.estop = False
            self.safety_mode = SafetyMode.NORMAL
            self.note("Emergency stop released: power on and release the brakes to continue")

    # ------------------------------------------------------------------ programs (script port)
    def run_program(self, program: Program) -> str | None:
        """A program arrived on a script port: run it (None), or why it cannot run."""
        if program.secondary:
            return None  # a lone command or a secondary program: nothing the sim's arm needs
        if self.robot_mode is not URRobotMode.RUNNING or self.safety_mode is not SafetyMode.NORMAL:
            why = f"program {program.name!r} not started: robot mode {self.robot_mode.name}, safety {self.safety_mode.name}"
            self.note(why)
            return why
        self.stop_program("a new program")
        self.program = program
        self.script = ControlScript(self, *program.register_offsets) if program.is_rtde_control else None
        self.runtime_state = RuntimeState.PLAYING
        self.note(f"program {program.name!r} started" + ("" if self.script else " (not ur_rtde's: idles)"))
        return None

    def play(self) -> bool:
        if self.program is None or self.runtime_state is RuntimeState.PLAYING:
            return self.runtime_state is RuntimeState.PLAYING
        return self.run_program(self.program) is None

    def stop_program(self, why: str) -> bool:
        if self.runtime_state is not RuntimeState.PLAYING:
            return False
        self.runtime_state = RuntimeState.STOPPED
        self.script = None
        if self.arm.moving:
            self.arm.stop(4.0)
        self.note(f"program stopped ({why})")
        return True

    # ------------------------------------------------------------------ RTDE inputs
    def apply_inputs(self, values: dict[str, Any]) -> None:
        """The fields of one received data package (already decoded by its recipe)."""
        for name, v in values.items():
            if name.startswith("input_int_register_"):
                self.in_int[int(name.rsplit("_", 1)[1])] = int(v)
                self.register_writes += 1
            elif name.startswith("input_double_register_"):
                self.in_double[int(name.rsplit("_", 1)[1])] = float(v)
        for mask_name, value_name, attr in (
            ("standard_digital_output_mask", "standard_digital_output", "standard_do"),
            ("configurable_digital_output_mask", "configurable_digital_output", "configurable_do"),
            ("tool_digital_output_mask", "tool_digital_output", "tool_do"),
        ):
            if mask_name in values and value_name in values:
                mask, val = int(values[mask_name]), int(values[value_name])
                setattr(self, attr, (getattr(self, attr) & ~mask) | (val & mask))
        if values.get("speed_slider_mask"):
            self.speed_slider = min(max(float(values.get("speed_slider_fraction", 1.0)), 0.0), 1.0)

    @property
    def digital_outputs(self) -> int:
        """``actual_digital_output_bits``: standard 0-7, configurable 8-15, tool 16-17."""
        return self.standard_do | (self.configurable_do << 8) | ((self.tool_do & 0b11) << 16)

    # ------------------------------------------------------------------ the control cycle
    def tick(self, dt: float = TICK_S) -> None:
        self.timestamp_s = round(self.timestamp_s + dt, 9)
        self.ticks += 1
        if self._mode_change_at is not None and self.timestamp_s >= self._mode_change_at - 1e-9:
            assert self._mode_target is not None
            if self._mode_target is URRobotMode.RUNNING and self.robot_mode is URRobotMode.POWER_ON:
                self.robot_mode = URRobotMode.IDLE  # passes through IDLE on its way
                self._mode_change_at = self.timestamp_s + self.config.brake_release_s
            else:
                self.robot_mode, self._mode_target, self._mode_change_at = self._mode_target, None, None
        if self.script is not None and self.runtime_state is RuntimeState.PLAYING:
            try:
                self.script.cycle()
            except SafetyViolation as exc:
                self.protective_stop(str(exc))
            except MotionFailure as exc:
                self.note(str(exc))
                self.stop_program("runtime error")
        if self.robot_mode is URRobotMode.RUNNING:
            try:
                self.arm.step(dt * self.speed_slider)
            except SafetyViolation as exc:
                self.protective_stop(str(exc))
        r = self.arm.ref
        st = self.engine.step(dt, r.q, r.qd, r.qdd)
        self.q, self.qd = st.q, st.qd
        self.tcp_force = st.tcp_force  # a twin's wrist wrench (what a guarded touch-down watches)
        self.digital_inputs = st.digital_inputs
        self.engine.set_digital_outputs(self.engine_digital_outputs)

    @property
    def engine_digital_outputs(self) -> int:
        """The outputs in the engines' convention (the Dobot's): cabinet from bit 0, the flange's from 32."""
        return (
            self.standard_do | (self.configurable_do << 8) | ((self.tool_do & 0b11) << ENGINE_TOOL_DO_SHIFT)
        )

    # ------------------------------------------------------------------ RTDE outputs
    def outputs(self, names: Iterable[str] = ()) -> dict[str, Any]:
        """Every output variable's value now, registers only those in ``names`` (the RTDE server
        picks the fields of each recipe)."""
        z6 = (0.0,) * 6
        status = RobotStatusBit(0)
        if self.robot_mode in (URRobotMode.POWER_ON, URRobotMode.IDLE, URRobotMode.RUNNING):
            status |= RobotStatusBit.POWER_ON
        if self.runtime_state is RuntimeState.PLAYING:
            status |= RobotStatusBit.PROGRAM_RUNNING
        out: dict[str, Any] = {
            "timestamp": self.timestamp_s,
            "target_q": tuple(self.arm.ref.q),
            "target_qd": tuple(self.arm.ref.qd),
            "target_qdd": tuple(self.arm.ref.qdd),
            "target_current": z6,
            "target_moment": z6,
            "actual_q": tuple(self.q),
            "actual_qd": tuple(self.qd),
            "actual_current": z6,
            "joint_control_output": z6,
            "actual_TCP_pose": self._tcp_pose(self.q),
            "actual_TCP_speed": z6,
            "actual_TCP_force": tuple(float(v) for v in self.tcp_force),
            "target_TCP_pose": self._tcp_pose(self.arm.ref.q),
            "target_TCP_speed": z6,
            "actual_digital_input_bits": self.digital_inputs,
            "joint_temperatures": (30.0,) * 6,
            "actual_execution_time": 0.2,
            "robot_mode": int(self.robot_mode),
            "joint_mode": (253,) * 6 if self.robot_mode is URRobotMode.RUNNING else (251,) * 6,
            "safety_mode": int(self.safety_mode),
            "safety_status": int(self.safety_mode),
            "actual_tool_accelerometer": (0.0, 0.0, 9.81),
            "speed_scaling": self.speed_slider,
            "target_speed_fraction": self.speed_slider,
            "actual_momentum": 0.0,
            "actual_main_voltage": 48.0,
            "actual_robot_voltage": 48.0 if status & RobotStatusBit.POWER_ON else 0.0,
            "actual_robot_current": 0.5,
            "actual_joint_voltage": (48.0,) * 6,
            "actual_digital_output_bits": self.digital_outputs,
            "runtime_state": int(self.runtime_state),
            "robot_status_bits": int(status),
            "safety_status_bits": int(self.safety_status_bits),
            "standard_analog_input0": 0.0,
            "standard_analog_input1": 0.0,
            "standard_analog_output0": 0.0,
            "standard_analog_output1": 0.0,
            "ft_raw_wrench": z6,
            "payload": self.payload_kg,
            "payload_cog": self.payload_cog,
            "payload_inertia": z6,
            "elbow_position": (0.0, 0.0, 0.0),
            "elbow_velocity": (0.0, 0.0, 0.0),
            "output_bit_registers0_to_31": 0,
            "output_bit_registers32_to_63": 0,
        }
        for name in names:
            reg = register(name)
            if reg is not None:
                table: list[int] | list[float]
                if reg[0] == "output":
                    table = self.out_int if reg[1] == "int" else self.out_double
                else:
                    table = self.in_int if reg[1] == "int" else self.in_double
                out[name] = table[reg[2]]
        return out

    def _tcp_pose(self, q: np.ndarray) -> tuple[float, ...]:
        """The TCP pose of ``q`` (forward kinematics with the program's TCP), cached: at rest or for
        actual and target alike it is the same pose every cycle."""
        key = q.tobytes() + self.arm.T_flange_tcp.tobytes()
        hit = self._pose_cache.get(key)
        if hit is None:
            if len(self._pose_cache) > 8:
                self._pose_cache.clear()
            hit = tuple(transform_to_pose(analytic.fk(self.spec, q, self.arm.T_flange_tcp)).tolist())
            self._pose_cache[key] = hit
        return hit

    @property
    def safety_status_bits(self) -> SafetyStatusBit:
        m = self.safety_mode
        bits = {
            SafetyMode.NORMAL: SafetyStatusBit.NORMAL_MODE,
            SafetyMode.REDUCED: SafetyStatusBit.REDUCED_MODE,
            SafetyMode.PROTECTIVE_STOP: SafetyStatusBit.PROTECTIVE_STOPPED
            | SafetyStatusBit.STOPPED_DUE_TO_SAFETY,
            SafetyMode.ROBOT_EMERGENCY_STOP: SafetyStatusBit.ROBOT_EMERGENCY_STOPPED
            | SafetyStatusBit.EMERGENCY_STOPPED
            | SafetyStatusBit.STOPPED_DUE_TO_SAFETY,
            SafetyMode.SYSTEM_EMERGENCY_STOP: SafetyStatusBit.SYSTEM_EMERGENCY_STOPPED
            | SafetyStatusBit.EMERGENCY_STOPPED
            | SafetyStatusBit.STOPPED_DUE_TO_SAFETY,
        }
        return bits.get(m, SafetyStatusBit.STOPPED_DUE_TO_SAFETY)
