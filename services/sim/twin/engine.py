"""TwinEngine: the MuJoCo cell behind the simulated Dobot controller (a ``MotionEngine``).

The controller calls :meth:`TwinEngine.step` every control tick (8 ms of sim time) with the joint
reference it produced; the engine sub-steps physics at the model timestep, tracking the reference
with PD + velocity feed-forward (one implicit-damped actuator per joint), inertia feed-forward
(M·qdd_ref) and gravity compensation (``gravcomp`` on the arm bodies) — the reference reaching the
drive ``world.variation.command_latency_s`` late (whole physics steps; 0 nominally) — and reports what a real
controller measures: joints, joint torques, the wrist force/torque, digital inputs, and a
collision description (alarm 117) when an arm or gripper geom presses on the table, the obstacle
or an object harder than ``collision_force_n``. The gripper follows the digital outputs.

Thread model: physics runs in the caller's thread (the controller's clock). ``lock`` guards the
MjData; renderers and evaluation code copy a :class:`TwinSnapshot` under it and work on their own
MjData.
"""

from __future__ import annotations

import collections
import numbers
import threading
from dataclasses import dataclass

import mujoco
import numpy as np

from services.common.errors import ExecutionError, InvalidInputError
from services.common.frames import finite_vector
from services.common.settings import Settings
from services.sim.engine import EngineState
from services.sim.twin.model import TwinWorld, build_world
from services.sim.twin.scene import Scene

Array = np.ndarray

MAX_STEP_S = 1.0
# A gripper's "object detected" output (Robotiq's gOBJ, DH's grip state): set when the closing fingers
# come to rest apart, held while they stay there, cleared when they close on again (the object slips
# out: the fingers follow it) or the gripper is commanded anew. Read as the fingers' speed at each
# instant, it flickered at 0.01-0.07 m/s while the pads settled on the rod during the lift (±0.7 mm),
# and the cycle took a rod in the jaws (21.3 mm apart) for a slip: false regrasps ended 4 of 200
# randomized trials.
OBJECT_DETECT_MIN_OPENING_M = 0.002  # fingers at rest this far apart or more: something is held
OBJECT_DETECT_MAX_SPEED_M_S = 0.01  # at rest
OBJECT_LOST_CLOSING_M = 0.003  # closed on this far past where they rested: the object is going
TOOL_DO_SHIFT = 32


@dataclass(frozen=True)
class TwinSnapshot:
    """A consistent copy of the physical state (for rendering and evaluation)."""

    time_s: float
    qpos: Array
    qvel: Array


class TwinEngine:
    """Physics twin of the cell; implements :class:`services.sim.engine.MotionEngine`."""

    def __init__(self, world: TwinWorld, q0: Array | None = None):
        self.world = world
        self.model = world.model
        self.data = mujoco.MjData(self.model)
        self.lock = threading.RLock()
        self._h = float(self.model.opt.timestep)
        kp = np.array(world.gains.kp)
        self._ff_ratio = np.array(world.gains.kv) / kp  # ctrl = q + (kv/kp)·qd  → PD + velocity FF
        self._debt_s = 0.0
        self._closed = False
        self._grip_closed = False
        self._object_at: float | None = None  # the opening the object-detected output was set at
        self._do_mask = 0
        self._hold_q: Array | None = None
        self._hold_ref: Array | None = None
        self._last_ref: Array | None = None
        self._subtree_mass = float(self.model.body_subtreemass[world.gripper_body])
        self._gravity = np.array(self.model.opt.gravity)
        self._Mqdd = np.zeros(self.model.nv)
        self._qdd_full = np.zeros(self.model.nv)
        self._force6 = np.zeros(6)
        # Command latency: the drive acts on the (actuator target, feed-forward torque) of this many
        # physics steps ago; the line is refilled with the held pose on reset and hold.
        self._latency_steps = round(world.variation.command_latency_s / self._h)
        self._delay: collections.deque[tuple[Array, Array]] = collections.deque()
        self.data.ctrl[world.grip_act] = world.stroke_m  # open
        self.data.qpos[world.finger_qpos] = world.stroke_m / 2
        self.reset(np.zeros(world.spec.dof) if q0 is None else q0)

    # --- MotionEngine -------------------------------------------------------------------------
    def reset(self, q: Array) -> None:
        qv = finite_vector(q, self.world.spec.dof, "reset joints (rad)")
        self._check_open()
        with self.lock:
            w, d = self.world, self.data
            d.qpos[w.arm_qpos] = qv
            d.qvel[w.arm_dof] = 0.0
            d.qacc_warmstart[:] = 0.0
            d.ctrl[w.arm_act] = qv
            d.qfrc_applied[:] = 0.0
            self._hold_q = self._hold_ref = self._last_ref = None
            self._debt_s = 0.0
            self._fill_delay(qv)
            mujoco.mj_forward(self.model, d)
            self._state = self._measure()

    def step(self, dt: float, q_ref: Array, qd_ref: Array, qdd_ref: Array) -> EngineState:
        if not (isinstance(dt, numbers.Real) and np.isfinite(dt) and 0 < dt <= MAX_STEP_S):
            raise InvalidInputError(f"step dt must be within (0, {MAX_STEP_S}] s, got {dt!r}")
        n = self.world.spec.dof
        q = finite_vector(q_ref, n, "q_ref (rad)")
        qd = finite_vector(qd_ref, n, "qd_ref (rad/s)")
        qdd = finite_vector(qdd_ref, n, "qdd_ref (rad/s²)")
        self._check_open()
        with self.lock:
            if self._hold_q is not None:
                if self._hold_ref is not None and np.array_equal(q, self._hold_ref):
                    q, qd, qdd = self._hold_q, np.zeros(n), np.zeros(n)
                else:
                    self._hold_q = self._hold_ref = None
            self._last_ref = np.asarray(q_ref, dtype=float).copy()
            self._advance(float(dt), q, qd, qdd)
            self._state = self._measure()
            return self._state

    def set_digital_outputs(self, outputs: int) -> None:
        if not isinstance(outputs, int | np.integer) or outputs < 0:
            raise InvalidInputError(f"digital output mask must be a non-negative integer, got {outputs!r}")
        g = self.world.gripper
        # The controller passes cabinet DOs in bits 0..31 and the flange's ToolDOs from bit 32.
        base = TOOL_DO_SHIFT if g.tool_outputs else 0
        close_on = bool((int(outputs) >> (base + g.close_do - 1)) & 1)
        if g.open_do is None:
            closed = close_on
        else:
            open_on = bool((int(outputs) >> (base + g.open_do - 1)) & 1)
            # Double-solenoid style: one output ON selects; both equal keeps the last state.
            closed = self._grip_closed if close_on == open_on else close_on
        with self.lock:
            self._do_mask = int(outputs)
            if closed != self._grip_closed:
                self._object_at = None  # a new grip: detected afresh
            self._grip_closed = closed
            self.data.ctrl[self.world.grip_act] = 0.0 if closed else self.world.stroke_m

    def hold(self) -> None:
        with self.lock:
            self._hold_q = self.data.qpos[self.world.arm_qpos].copy()
            self._hold_ref = None if self._last_ref is None else self._last_ref.copy()
            self.data.ctrl[self.world.arm_act] = self._hold_q
            self.data.qfrc_applied[:] = 0.0
            self._fill_delay(self._hold_q)  # a stop acts at once, whatever was in flight

    def close(self) -> None:
        self._closed = True

    # --- observation ----------------------------------------------------------------------------
    def state(self) -> EngineState:
        with self.lock:
            return self._state

    @property
    def time_s(self) -> float:
        return float(self.data.time)

    @property
    def scene(self) -> Scene:
        return self.world.scene

    @property
    def gripper_closed(self) -> bool:
        """The commanded gripper state (from the digital outputs)."""
        return self._grip_closed

    @property
    def gripper_opening_m(self) -> float:
        """Measured distance between the pads (what a gripper's position feedback would read)."""
        with self.lock:
            return float(self.data.qpos[self.world.finger_qpos].sum())

    def snapshot(self) -> TwinSnapshot:
        with self.lock:
            return TwinSnapshot(float(self.data.time), self.data.qpos.copy(), self.data.qvel.copy())

    def settle(self, duration_s: float) -> EngineState:
        """Hold the arm where it is and let physics run (evaluation helper)."""
        with self.lock:
            q = self.data.qpos[self.world.arm_qpos].copy()
        zeros = np.zeros_like(q)
        state = self.state()
        steps = max(1, round(duration_s / 0.008))
        for _ in range(steps):
            state = self.step(0.008, q, zeros, zeros)
        return state

    # --- internals ------------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise ExecutionError("the twin engine is closed")

    def _fill_delay(self, q: Array) -> None:
        zeros = np.zeros(self.model.nv)
        self._delay.clear()
        for _ in range(self._latency_steps):
            self._delay.append((np.array(q, dtype=float), zeros))

    def _advance(self, dt: float, q: Array, qd: Array, qdd: Array) -> None:
        w, m, d = self.world, self.model, self.data
        total = self._debt_s + dt
        n_sub = int(np.floor(total / self._h + 1e-9))
        self._debt_s = total - n_sub * self._h
        if n_sub == 0:
            return
        # Inertia feed-forward M(q)·qdd_ref on the arm joints, once per tick.
        self._qdd_full[:] = 0.0
        self._qdd_full[w.arm_dof] = qdd
        mujoco.mj_mulM(m, d, self._Mqdd, self._qdd_full)
        d.qfrc_applied[:] = 0.0
        d.qfrc_applied[w.arm_dof] = self._Mqdd[w.arm_dof]
        ff = self._ff_ratio * qd
        t_end = n_sub * self._h
        frc_now = d.qfrc_applied.copy() if self._latency_steps else d.qfrc_applied
        for k in range(n_sub):
            # The reference is for the end of the tick; earlier sub-steps follow it back along qd.
            target = q - qd * (t_end - (k + 1) * self._h) + ff
            if self._latency_steps:
                self._delay.append((target, frc_now))
                target, frc = self._delay.popleft()
                d.qfrc_applied[:] = frc
            d.ctrl[w.arm_act] = target
            mujoco.mj_step(m, d)

    def _measure(self) -> EngineState:
        w, d = self.world, self.data
        effort = (d.qfrc_actuator + d.qfrc_gravcomp + d.qfrc_applied)[w.arm_dof]
        return EngineState(
            q=d.qpos[w.arm_qpos].copy(),
            qd=d.qvel[w.arm_dof].copy(),
            effort=effort.copy(),
            tcp_force=self._wrist_wrench(),
            digital_inputs=self._digital_inputs(),
            collision=self._collision(),
        )

    def _wrist_wrench(self) -> Array:
        """Force/torque the environment exerts on the gripper, base frame, gripper weight removed.

        Like a tared wrist F/T sensor with the tool load configured: holding the 0.1 kg rod reads
        fz ≈ −0.98 N; touching it down on the table brings fz back toward 0.
        """
        w, d = self.world, self.data
        R = d.site_xmat[w.ft_site].reshape(3, 3)
        f_sensor = R @ d.sensordata[w.force_adr : w.force_adr + 3]
        t_sensor = R @ d.sensordata[w.torque_adr : w.torque_adr + 3]
        weight = self._subtree_mass * self._gravity
        lever = d.subtree_com[w.gripper_body] - d.site_xpos[w.ft_site]
        # The sensors read what the parent (link6) exerts on the gripper subtree; statics of the
        # subtree give the environment's share.
        force = -f_sensor - weight
        torque = -t_sensor - np.cross(lever, weight)
        return np.concatenate([force, torque])

    def _digital_inputs(self) -> int:
        di = self.world.gripper.object_di
        if di is None or not self._grip_closed:
            self._object_at = None
            return 0
        d, w = self.data, self.world
        opening = float(d.qpos[w.finger_qpos].sum())
        at_rest = float(abs(d.qvel[w.finger_dof].sum())) < OBJECT_DETECT_MAX_SPEED_M_S
        if opening <= OBJECT_DETECT_MIN_OPENING_M or (
            self._object_at is not None and opening < self._object_at - OBJECT_LOST_CLOSING_M
        ):
            self._object_at = None  # closed on past the object: it is gone (or going)
        elif at_rest and (self._object_at is None or opening > self._object_at):
            self._object_at = opening  # rests on it (the highest rest: settling never lowers the mark)
        return (1 << (di - 1)) if self._object_at is not None else 0

    def _collision(self) -> str | None:
        w, d = self.world, self.data
        ncon = d.ncon
        if ncon == 0:
            return None
        g = np.asarray(d.contact.geom[:ncon])
        g1, g2 = g[:, 0], g[:, 1]

        def hits(a: Array, b: Array) -> Array:
            return w.robot_geom[a] & (w.env_geom[b] | (w.object_geom[b] & ~w.finger_geom[a]))

        candidates = np.flatnonzero(hits(g1, g2) | hits(g2, g1))
        worst, worst_i = 0.0, -1
        for i in candidates:
            mujoco.mj_contactForce(self.model, d, int(i), self._force6)
            if self._force6[0] > worst:
                worst, worst_i = float(self._force6[0]), int(i)
        if worst_i < 0 or worst < w.twin.physics.collision_force_n:
            return None
        a, b = int(g1[worst_i]), int(g2[worst_i])
        robot, other = (a, b) if w.robot_geom[a] else (b, a)
        return f"collision: {w.geom_name(robot)} pressed on {w.geom_name(other)} with {worst:.0f} N"


def create_twin_engine(settings: Settings, seed: int | None = None) -> TwinEngine:
    """The twin for ``settings`` (robot model, gripper, ``sim.twin``) and a seeded scene.

    ``seed`` defaults to ``settings.sim.seed``; the arm starts at ``sim.twin.initial_joints_deg``.
    """
    world = build_world(settings, seed)
    return TwinEngine(world, np.deg2rad(np.asarray(settings.sim.twin.initial_joints_deg, dtype=float)))
