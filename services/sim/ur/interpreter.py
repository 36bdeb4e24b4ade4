"""What ur_rtde's control script does on a controller, one control cycle at a time (pure).

The script (``scripts/rtde_control.script`` in ur_rtde, uploaded by RTDEControlInterface) reads a
command number from ``input_int_register_0`` and its arguments from the input registers, and answers
through ``output_int_register_0`` (1 ready for a command, 2 done with it) and ``output_int_register_2``
(the async operation's progress). Its main loop, per cycle:

- a real-time command (servoJ, speedJ, …): process it, signal ready;
- no command (0): not executing any more, signal ready;
- any other command, unless already executing it: process it (a synchronous move blocks the loop
  until the arm stops), signal done, remember it is executing (ur_rtde then clears the command).

A command the registers still hold from before this run of the script started (a servoJ streamed
into a protective stop, say) is not taken up: the script acts on what its client writes while it
runs (a sim choice; replaying a stale servo target after an unlock would jump the arm).

Register numbers carry the offset ur_rtde injected (0, or 24 for the upper range). Commands the sim
does not model stop the program with a message, so the client's call fails instead of pretending.
docs/ur/rtde.md §4 lists each command's registers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from services.kinematics import analytic
from services.rtde.codes import REALTIME_COMMANDS, ScriptCommand, ScriptState
from services.rtde.poses import pose_to_transform
from services.sim.ur.arm import MotionFailure, MotionKind

if TYPE_CHECKING:
    from services.sim.ur.controller import URController

C = ScriptCommand


class ControlScript:
    def __init__(self, controller: URController, int_offset: int = 0, float_offset: int = 0):
        self.c = controller
        self.io, self.fo = int_offset, float_offset
        self.executing = False
        self._blocked: Callable[[], bool] | None = None  # a synchronous command waits for this
        self._async_running = False
        self._wr_count = 0
        self._op_id = 0
        self._writes_at_start = controller.register_writes
        self._write_async(-1)  # reset_async_progress()
        self._signal(ScriptState.READY_FOR_CMD)

    # ------------------------------------------------------------ registers
    def _int(self, i: int) -> int:
        return self.c.in_int[i + self.io]

    def _double(self, i: int) -> float:
        return self.c.in_double[i + self.fo]

    def _doubles(self, i: int, n: int = 6) -> np.ndarray:
        return np.array([self._double(i + k) for k in range(n)])

    def _signal(self, state: ScriptState) -> None:
        self.c.out_int[0 + self.io] = int(state)

    def _write_out_int(self, i: int, value: int) -> None:
        self.c.out_int[i + self.io] = value

    def _write_async(self, value: int) -> None:
        """write_async_progress_register: change count bits 16-23, op id 24-30, running bit 15."""
        self._wr_count = (self._wr_count + 1) % 128
        if value == 0:
            self._op_id = (self._op_id + 1) % 128
        reg = self._wr_count * 65536 + self._op_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self._write_out_int(2, reg)

    # ------------------------------------------------------------ one cycle of the main loop
    def cycle(self) -> None:
        if self._async_running and self.c.arm.kind not in (
            MotionKind.MOVEJ,
            MotionKind.MOVEL,
            MotionKind.STOP,
        ):
            self._async_running = False
            self._write_async(-1)  # signal_async_operation_finished() at the end of the move thread
        if self._blocked is not None:
            if not self._blocked():
                return  # a synchronous move: the script sits in movej/movel/stopj
            self._blocked = None
            self._signal(ScriptState.DONE_WITH_CMD)
            self.executing = True
            return
        cmd = self._int(0) if self.c.register_writes != self._writes_at_start else int(C.NO_CMD)
        if cmd in REALTIME_COMMANDS:
            self._process(cmd)
            self._signal(ScriptState.READY_FOR_CMD)
        elif cmd == C.NO_CMD:
            self.executing = False
            self._signal(ScriptState.READY_FOR_CMD)
        elif not self.executing:
            self._process(cmd)
            if self.c.script is not self:
                return  # the command ended the program (stop script, protective stop)
            if self._blocked is None:
                self._signal(ScriptState.DONE_WITH_CMD)
                self.executing = True

    def _arm_at_rest(self) -> bool:
        return not self.c.arm.moving

    # ------------------------------------------------------------ process_cmd
    def _process(self, cmd: int) -> None:
        arm = self.c.arm
        if cmd in (C.MOVEJ, C.MOVEJ_IK, C.MOVEL, C.MOVEL_FK):
            target = self._doubles(0)
            v, a, asynchronous = self._double(6), self._double(7), self._int(1) == 1
            self._stop_async_move()
            if cmd == C.MOVEJ:
                arm.movej(target, v, a)
            elif cmd == C.MOVEJ_IK:
                T = pose_to_transform(target) @ np.linalg.inv(arm.T_flange_tcp)
                try:
                    q = analytic.solve_nearest(self.c.spec, T, arm.ref.q)
                except Exception as exc:  # IKFailureError: the script's get_inverse_kin fails
                    raise MotionFailure(f"movej_ik: inverse kinematics failed: {exc}") from exc
                arm.movej(q, v, a)
            elif cmd == C.MOVEL:
                arm.movel(pose_to_transform(target), v, a)
            else:
                arm.check_joints(target, "movel_fk")
                arm.movel(analytic.fk(self.c.spec, target, arm.T_flange_tcp), v, a)
            if asynchronous:
                self._async_running = True
                self._write_async(0)  # signal_async_operation_started()
            else:
                self._blocked = self._arm_at_rest
        elif cmd == C.SERVOJ:
            arm.servoj(self._doubles(0), self._double(8))
        elif cmd == C.SPEEDJ:
            arm.speedj(self._doubles(0), self._double(6))
        elif cmd in (C.SPEED_STOP, C.SERVO_STOP):
            if (cmd == C.SPEED_STOP and arm.kind is MotionKind.SPEEDJ) or (
                cmd == C.SERVO_STOP and arm.kind is MotionKind.SERVOJ
            ):
                arm.stop(self._double(0))
                if cmd == C.SERVO_STOP:  # servo_stop ends in stopl(): it returns once stopped
                    self._blocked = self._arm_at_rest
        elif cmd in (C.STOPJ, C.STOPL):
            asynchronous = self._int(1) == 1
            self._stop_async_move()
            arm.stop(self._double(0))
            if asynchronous:
                self._async_running = True
                self._write_async(0)
            else:
                self._blocked = self._arm_at_rest
        elif cmd == C.SET_TCP:
            arm.T_flange_tcp = pose_to_transform(self._doubles(0))
        elif cmd == C.SET_PAYLOAD:
            self.c.payload_kg = self._double(0)
            self.c.payload_cog = (self._double(1), self._double(2), self._double(3))
        elif cmd == C.PROTECTIVE_STOP:
            self.c.protective_stop("protective_stop() called by the program")
        elif cmd == C.IS_STEADY:
            self._write_out_int(1, int(not arm.moving and float(np.max(np.abs(self.c.qd))) < 1e-6))
        elif cmd == C.STOP_SCRIPT:
            self.c.stop_program("stop script command")
        elif cmd == C.WATCHDOG:
            pass
        else:
            self.c.note(f"command {cmd} of ur_rtde's script is not simulated")
            self.c.stop_program(f"unsupported command {cmd}")

    def _stop_async_move(self) -> None:
        if self._async_running:
            self._async_running = False
            self._write_async(-1)  # the killed move thread cannot signal: stop_async_move() does
