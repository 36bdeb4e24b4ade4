"""Pluggable motion engines behind the simulated Dobot controller.

The simulated controller (``services.sim.controller``) turns protocol commands
into a joint reference (position, velocity, acceleration) sampled every control
tick, in *sim time*. An engine makes the arm follow that reference and reports
what a real controller would measure. ``KinematicEngine`` follows it exactly;
the physics twin (``services.sim.twin``) tracks it with PD + feed-forward in
MuJoCo, so measured joints lag, objects are pushed, and collisions happen.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass
class EngineState:
    """What the controller can measure after a step (SI units, radians)."""

    q: np.ndarray
    qd: np.ndarray
    effort: np.ndarray = field(default_factory=lambda: np.zeros(6))
    tcp_force: np.ndarray = field(default_factory=lambda: np.zeros(6))  # fx,fy,fz N; tx,ty,tz N·m
    digital_inputs: int = 0  # DI bit mask (bit n-1 = DI_n)
    collision: str | None = None  # description of an arm collision, None when clear


@runtime_checkable
class MotionEngine(Protocol):
    """Advances the arm (and whatever else it simulates) in sim time."""

    def reset(self, q: np.ndarray) -> None:
        """Place the arm at ``q`` at rest."""

    def step(self, dt: float, q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray) -> EngineState:
        """Advance by ``dt`` seconds of sim time tracking the reference; return the measured state."""

    def set_digital_outputs(self, outputs: int) -> None:
        """The controller's DO bit mask changed (the gripper is wired to it)."""

    def hold(self) -> None:
        """Motion was stopped (Stop/e-stop/alarm): hold the current measured position."""

    def close(self) -> None:
        """Release resources (threads, renderers)."""


class KinematicEngine:
    """Ideal tracking: the measured joints are exactly the reference."""

    def __init__(self, q0: np.ndarray | None = None, dof: int = 6):
        self._q = np.zeros(dof) if q0 is None else np.asarray(q0, dtype=float).copy()
        self._qd = np.zeros_like(self._q)
        self._do = 0

    def reset(self, q: np.ndarray) -> None:
        self._q = np.asarray(q, dtype=float).copy()
        self._qd = np.zeros_like(self._q)

    def step(self, dt: float, q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray) -> EngineState:
        self._q = np.asarray(q_ref, dtype=float).copy()
        self._qd = np.asarray(qd_ref, dtype=float).copy()
        return self.state()

    def state(self) -> EngineState:
        return EngineState(q=self._q.copy(), qd=self._qd.copy())

    def set_digital_outputs(self, outputs: int) -> None:
        self._do = outputs

    def hold(self) -> None:
        self._qd = np.zeros_like(self._q)

    def close(self) -> None:
        pass
