"""The UR controller link: :class:`services.robot.link.ControllerLink` over SDU's ur_rtde.

ur_rtde's calls are blocking C++: every one runs on this link's own worker thread (one, so calls to a
controller are serialised as they are on its sockets), never on the event loop. Its methods release
Python's GIL; its *constructors* do not (pybind11 ``py::init``), so the loop stands still while an
interface connects — milliseconds against a controller that answers, which is why the simulated UR
runs in a process of its own (:mod:`services.sim.ur.process`).

Feedback: a poller thread reads the receive interface's newest sample whenever its ``timestamp``
changes (500 Hz on an e-Series) and hands it to the loop; every wait is on that clock.

Motion: moveJ/moveL are sent asynchronous (the script's move thread; ``output_int_register_2`` says
when it ends), so a stop is never queued behind a move. ServoJ targets are queued here and sent one
per ``t`` of controller time (UR's servoj reaches a target in ``t``; the Dobot queues them itself),
which gives the driver the queue and ``current_command_id`` (the command executing, as a Dobot's
CurrentCommandId) its flow control and execution monitor expect. All safety
checks stay in the shared driver; the controller's own protective stop is reported as an alarm.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import random
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike

from services.common.errors import (
    ControllerError,
    EmergencyStopError,
    ExecutionError,
    InvalidInputError,
    RobotCommunicationError,
    TrajectoryExecutionError,
)
from services.common.settings.robot import ReconnectSettings
from services.dobot import RobotMode
from services.kinematics.robot_models import RobotSpec
from services.robot.feedback import REST_SPEED_RAD_S, ClientState, FeedbackState, LinkState
from services.robot.ur import rtde_api
from services.robot.ur.feedback import URSample, describe, to_feedback
from services.robot.ur.io_client import RTDEOutputs
from services.robot.ur.stream import FeedbackStream
from services.rtde.codes import SafetyMode

log = logging.getLogger("pickplace.robot.ur")

T = TypeVar("T")
POLL_S = 0.0005  # the poller looks for a new sample 4x per 2 ms cycle
SERVO_LOOKAHEAD_S = 0.1  # ur_rtde accepts 0.03-0.2
SERVO_GAIN = 300  # ur_rtde accepts 100-2000
# A stream's end: servoStop once the controller's reference is at the last target, or this long (of
# controller time) after that target's t at most
SERVO_END_TOLERANCE_RAD = 1e-5
SERVO_END_GRACE_S = 0.2
STOP_DECEL_RAD_S2 = 4.0
TOOL_SPEED_MAX_M_S = 1.0  # what a 100 % MovL ratio asks of the tool
TOOL_ACC_MAX_M_S2 = 2.5
ENABLE_TIMEOUT_S = 30.0  # controller time for power on + brake release (a real arm takes ~15 s)
# After a stop the arm still brakes (and a physical one settles behind its reference): it counts as
# moving, as a Dobot reports RUNNING, until no joint turns faster than REST_SPEED_RAD_S, or for at most so long
# "Cannot unlock protective stop until 5s after occurrence. …": the controller's own unlock delay
UNLOCK_TOO_EARLY = re.compile(r"^Cannot unlock protective stop until (\d+(?:\.\d+)?)s after occurrence")
STOP_SETTLE_MAX_S = 1.0


RUNNING_WORDS = "Robotmode: RUNNING"  # the dashboard's answer once the brakes are released
REFUSAL_SETTLE_S = 0.1  # controller time for the receive stream to show why a command was refused


def _halted(fb: FeedbackState) -> bool:
    return fb.in_error or fb.estop or fb.robot_mode in (RobotMode.DISABLED, RobotMode.POWER_OFF)


@dataclass
class _Servo:
    id: int
    q: np.ndarray
    t_s: float


class URLink(FeedbackStream):
    def __init__(
        self,
        host: str,
        spec: RobotSpec,
        *,
        request_timeout_s: float = 2.0,
        feedback_timeout_s: float = 1.0,
        reconnect: ReconnectSettings | None = None,
        frequency_hz: float = 500.0,
    ):
        super().__init__(host, feedback_timeout_s)
        self.spec = spec
        self.request_timeout_s = request_timeout_s
        self.reconnect = reconnect or ReconnectSettings()
        self.frequency_hz = frequency_hz
        self._io = rtde_api.Interfaces()
        self._outputs = RTDEOutputs(host)
        self._worker = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix=f"ur-{host}")
        self._loop: asyncio.AbstractEventLoop | None = None
        self._poller: threading.Thread | None = None
        self._poll_stop = threading.Event()
        self._sample: URSample | None = None
        self._speed_ratio = 100
        self._acc_ratio = 100
        self._next_id = 0
        self.current_command_id = 0
        self._move: tuple[int, int] | None = None  # (command id, async op id) of the running move
        self._servo_queue: deque[_Servo] = deque()
        self._servo_sent: _Servo | None = None
        self._servo_sent_ms = 0
        self._servo_busy = False
        self._estop_latched = False
        self._stopping_since_s: float | None = None  # controller time of a stop the arm still brakes from
        self._protective_since_ms: int | None = None  # controller time the protective stop was first seen
        self._reconnect_task: asyncio.Task[None] | None = None
        self.samples = 0

    # ------------------------------------------------------------------ threads
    async def _call(self, what: str, fn: Callable[[], T], timeout_s: float | None = None) -> T:
        """Run one blocking ur_rtde call on the worker thread."""
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(timeout_s or max(self.request_timeout_s, 10.0)):
                return await loop.run_in_executor(self._worker, fn)
        except TimeoutError:
            raise RobotCommunicationError(f"UR {self.host}: {what} did not return in time") from None
        except RuntimeError as exc:  # ur_rtde throws std::runtime_error / logic_error
            raise RobotCommunicationError(f"UR {self.host}: {what} failed: {exc}") from exc

    # ------------------------------------------------------------------ lifecycle
    async def connect(self) -> None:
        if self.state is ClientState.CLOSED:
            raise RuntimeError("UR link is closed")
        self._loop = asyncio.get_running_loop()
        self.state = ClientState.CONNECTING
        await self._call("connect", lambda: self._io.open(self.host, self.frequency_hz))
        self._start_poller()
        await self.next_feedback(max(self.feedback_timeout_s, 2.0))
        self.link = LinkState.UP
        self.state = ClientState.CONNECTED
        fb = self._sample
        if fb is not None and fb.robot_mode == 7:  # brakes released already: take control now
            await self._ensure_control()

    async def close(self) -> None:
        if self.state is ClientState.CLOSED:
            return
        self.state = ClientState.CLOSED
        self.link = LinkState.DOWN
        if self._reconnect_task is not None:
            self._reconnect_task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._reconnect_task
        self._stop_poller()
        await self._outputs.close()
        with contextlib.suppress(Exception):
            await self._call("close", self._io.close, timeout_s=10.0)
        self._worker.shutdown(wait=False)
        self._fail_waiters(RobotCommunicationError("UR link closed"))

    def _start_poller(self) -> None:
        self._poll_stop.clear()
        self._poller = threading.Thread(target=self._poll, name=f"ur-feedback-{self.host}", daemon=True)
        self._poller.start()

    def _stop_poller(self) -> None:
        self._poll_stop.set()
        if self._poller is not None:
            self._poller.join(2.0)
        self._poller = None

    def _poll(self) -> None:
        """Poller thread: each new sample to the loop; a dead receive interface ends the link."""
        last = -1.0
        stale_since = time.monotonic()
        loop = self._loop
        assert loop is not None
        while not self._poll_stop.is_set():
            try:
                sample = self._io.sample(last)
            except Exception as exc:  # the receive interface died: the loop decides what next
                loop.call_soon_threadsafe(self._lost, f"RTDE receive failed: {exc}")
                return
            now = time.monotonic()
            if sample is None:
                if now - stale_since > self.feedback_timeout_s:
                    loop.call_soon_threadsafe(self._lost, f"no RTDE data for {self.feedback_timeout_s:.1f}s")
                    return
                time.sleep(POLL_S)
                continue
            stale_since, last = now, sample.timestamp_s
            loop.call_soon_threadsafe(self._on_sample, sample)

    # ------------------------------------------------------------------ feedback (loop thread)
    def _moving(self) -> bool:
        return (
            self._move is not None
            or self._servo_sent is not None
            or bool(self._servo_queue)
            or self._servo_busy
            or self._stopping_since_s is not None
        )

    def _on_sample(self, s: URSample) -> None:
        if self.state is ClientState.CLOSED:
            return
        self.samples += 1
        self._sample = s
        if self._move is not None:
            _, op = self._move
            status = self._io.async_status()
            if status is not None and (status[1] != op or not status[0]):
                self._move = None
        if self._stopping_since_s is not None and (
            max(abs(v) for v in s.qd) < REST_SPEED_RAD_S
            or s.timestamp_s - self._stopping_since_s > STOP_SETTLE_MAX_S
        ):
            self._stopping_since_s = None
        fb = to_feedback(
            s,
            moving=self._moving(),
            current_command_id=self.current_command_id,
            estop_latched=self._estop_latched,
        )
        if fb.in_error or fb.estop:  # the controller halted: nothing queued here will run
            self._abandon_motion()
        if s.safety_mode != SafetyMode.PROTECTIVE_STOP:
            self._protective_since_ms = None
        elif self._protective_since_ms is None:
            self._protective_since_ms = fb.timestamp_ms
        self._publish(fb)
        self._pump_servo(fb)

    def _lost(self, reason: str) -> None:
        if self.state is ClientState.CLOSED or self.link is not LinkState.UP:
            return
        log.warning("UR %s link lost: %s", self.host, reason)
        self.link = LinkState.RECONNECTING
        self.state = ClientState.DISCONNECTED
        self.link_epoch += 1
        self._abandon_motion()
        self._fail_waiters(RobotCommunicationError(f"robot link lost: {reason}"))
        self._reconnect_task = asyncio.get_running_loop().create_task(
            self._reconnect_loop(), name=f"ur-reconnect-{self.host}"
        )

    async def _reconnect_loop(self) -> None:
        """Tear every interface down and open them again, with capped jittered backoff, for as long
        as the link lives."""
        self._stop_poller()
        await self._outputs.close()
        attempt = 0
        while self.state is not ClientState.CLOSED:
            with contextlib.suppress(Exception):
                await self._call(
                    "close for reconnect", lambda: self._io.close(graceful=False), timeout_s=15.0
                )
            try:
                await self._call("reconnect", lambda: self._io.open(self.host, self.frequency_hz))
                self._wake_error = None
                self._start_poller()
                await self.next_feedback(max(self.feedback_timeout_s, 2.0))
            except RobotCommunicationError as exc:
                self._stop_poller()
                cap = min(self.reconnect.max_delay_s, self.reconnect.base_delay_s * 2 ** min(attempt, 16))
                attempt += 1
                log.info("UR %s reconnect attempt %d failed: %s", self.host, attempt, exc)
                await asyncio.sleep(random.uniform(cap / 2, cap))
                continue
            self.link = LinkState.UP
            self.state = ClientState.CONNECTED
            log.warning("UR %s link restored", self.host)
            return

    def _abandon_motion(self) -> None:
        self._servo_queue.clear()
        self._servo_sent = None
        self._stopping_since_s = None
        if self._move is not None:
            self._move = None

    async def wait_motion_done(self, result_id: int | None, timeout_s: float) -> FeedbackState:
        """Until command ``result_id`` is done and the arm at rest; ``timeout_s`` of controller time."""
        epoch = self.link_epoch
        fb = self._feedback if self._feedback is not None else await self.next_feedback()
        deadline_ms = fb.timestamp_ms + timeout_s * 1000.0
        while True:
            if fb.estop:
                raise EmergencyStopError("emergency stop is active; motion aborted")
            if fb.in_error:
                assert self._sample is not None
                ids, text = await self.describe_alarms()
                raise ControllerError(f"controller stopped motion {result_id}: {text}", alarms=tuple(ids))
            if fb.robot_mode in (RobotMode.DISABLED, RobotMode.POWER_OFF):
                raise ExecutionError(f"robot is {RobotMode.name_of(fb.robot_mode)} during motion {result_id}")
            done = result_id is None or fb.current_command_id >= result_id
            if done and fb.robot_mode == RobotMode.ENABLE:
                return fb
            if fb.timestamp_ms >= deadline_ms:
                raise TrajectoryExecutionError(
                    f"motion {result_id} not finished within {timeout_s:.1f}s of controller time "
                    f"(current command {fb.current_command_id})"
                )
            fb = await self.next_feedback()
            if self.link_epoch != epoch:
                raise RobotCommunicationError(f"robot link lost during motion {result_id}")

    # ------------------------------------------------------------------ power, errors, stops
    async def _ensure_control(self) -> None:
        await self._call("start the control script", self._io.ensure_control, timeout_s=15.0)

    async def enable(self, load_kg: float = 0.0) -> None:
        if self._estop_latched:
            raise EmergencyStopError("software emergency stop is pressed; release it before enabling")
        s = self._sample
        if s is not None and s.estop:
            raise EmergencyStopError("the robot's emergency stop is active")
        await self._call("power on", lambda: self._io.dashboard("power on"))
        await self._call("brake release", lambda: self._io.dashboard("brake release"))
        # the dashboard answers with the controller's state now; the newest RTDE sample may predate
        # the commands (a power off just sent still shows RUNNING there)
        fb = self._feedback if self._feedback is not None else await self.next_feedback()
        deadline_ms = fb.timestamp_ms + ENABLE_TIMEOUT_S * 1000.0
        while (
            mode := await self._call("robotmode", lambda: self._io.dashboard("robotmode"))
        ) != RUNNING_WORDS:
            fb = await self.next_feedback()
            if fb.timestamp_ms > deadline_ms:
                raise ControllerError(
                    f"UR {self.host} not ready {ENABLE_TIMEOUT_S:.0f}s after brake release: {mode}"
                )
        await self._ensure_control()
        if load_kg > 0:
            await self._call(
                "setPayload", lambda: self._io.control_call("setPayload", load_kg, [0.0, 0.0, 0.0])
            )

    async def disable(self) -> None:
        self._abandon_motion()
        await self._call("power off", lambda: self._io.dashboard("power off"))

    async def clear_error(self) -> None:
        """Unlock a protective stop; one asked for before the controller's unlock delay has run (5 s
        on an e-Series) waits for it on the controller's clock, from when the stop was first seen."""
        reply = await self._call(
            "unlock protective stop", lambda: self._io.dashboard("unlock protective stop")
        )
        early = UNLOCK_TOO_EARLY.match(reply)
        if early is not None:
            await self.wait_controller_time(float(early.group(1)), since_ms=self._protective_since_ms)
            reply = await self._call(
                "unlock protective stop", lambda: self._io.dashboard("unlock protective stop")
            )
        if reply != "Protective stop releasing":
            raise ControllerError(f"UR {self.host} refused to unlock the protective stop: {reply}")
        await self._call("close safety popup", lambda: self._io.dashboard("close safety popup"))

    async def stop(self) -> None:
        self._abandon_motion()
        if self._sample is not None:  # moving (RUNNING) until the arm is at rest
            self._stopping_since_s = self._sample.timestamp_s
        self._next_id += 1
        self.current_command_id = self._next_id  # everything issued before the stop is over
        await self._call("stop", lambda: self._io.stop(STOP_DECEL_RAD_S2))

    async def emergency_stop(self, press: bool = True) -> None:
        """A UR has no protocol command for its e-stop circuit: a pressed software e-stop powers the
        arm off (brakes on) and latches here until released; ``enable`` is refused meanwhile."""
        if press:
            self._estop_latched = True
            self._abandon_motion()
            await self._call("power off (e-stop)", lambda: self._io.dashboard("power off"))
        else:
            self._estop_latched = False

    async def describe_alarms(self) -> tuple[list[int], str]:
        s = self._sample
        if s is None:
            return [], "no feedback yet"
        return [int(s.safety_mode)], describe(s)

    async def speed_factor(self, ratio: int) -> None:
        self._speed_ratio = int(ratio)

    async def acceleration_ratio(self, ratio: int) -> None:
        self._acc_ratio = int(ratio)

    # ------------------------------------------------------------------ motion
    def _new_id(self) -> int:
        self._next_id += 1
        return self._next_id

    def _check_link(self, what: str) -> None:
        """What the Dobot's controller answers with an ErrorID, a UR shows in its state: checked here."""
        if self.link is not LinkState.UP:
            raise RobotCommunicationError(f"UR link is {self.link.value}: {what} not sent")
        fb = self._feedback
        if fb is not None and fb.estop:
            raise EmergencyStopError(f"emergency stop is active: {what} not sent")

    def _ratios(self, a: int | None, v: int | None) -> tuple[float, float]:
        return (self._speed_ratio / 100.0) * ((v or 100) / 100.0), (self._acc_ratio / 100.0) * (
            (a or 100) / 100.0
        )

    async def _move_async(self, name: str, q: np.ndarray, v: float, acc: float) -> int:
        self._check_link(name)
        await self._settle_servo()
        ok, op = await self._call(name, lambda: self._io.move(name, q.tolist(), v, acc))
        if not ok:
            # ur_rtde saw why on its own connection; the receive stream shows it a cycle or two later
            with contextlib.suppress(TimeoutError):
                await self.wait_controller(_halted, REFUSAL_SETTLE_S)
            ids, text = await self.describe_alarms()
            raise ControllerError(f"UR {self.host} refused {name}: {text}", alarms=tuple(ids))
        mid = self._new_id()
        self._move = (mid, op)
        self.current_command_id = mid  # executing (a Dobot's CurrentCommandId); done when at rest
        return mid

    async def mov_j(
        self, q: ArrayLike, a: int | None = None, v: int | None = None, cp: int | None = None
    ) -> int | None:
        vr, ar = self._ratios(a, v)
        qv = np.asarray(q, dtype=float)
        return await self._move_async(
            "moveJ",
            qv,
            float(np.min(self.spec.max_velocity)) * vr,
            float(np.min(self.spec.max_acceleration)) * ar,
        )

    async def mov_l(self, q: ArrayLike, a: int | None = None, v: int | None = None) -> int | None:
        vr, ar = self._ratios(a, v)
        return await self._move_async(
            "moveL_FK", np.asarray(q, dtype=float), TOOL_SPEED_MAX_M_S * vr, TOOL_ACC_MAX_M_S2 * ar
        )

    async def servo_j(self, q: ArrayLike, t_s: float) -> int | None:
        self._check_link("servoJ")
        item = _Servo(self._new_id(), np.asarray(q, dtype=float).copy(), float(t_s))
        self._servo_queue.append(item)
        if self._feedback is not None:
            self._pump_servo(self._feedback)
        return item.id

    def _pump_servo(self, fb: FeedbackState) -> None:
        """Send the next queued target once the previous one's ``t`` has run on the controller."""
        if self._servo_busy:
            return
        sent = self._servo_sent
        if sent is not None and fb.timestamp_ms < self._servo_sent_ms + sent.t_s * 1000.0 - 1e-6:
            return
        if (
            sent is not None
            and not self._servo_queue
            and float(np.max(np.abs(fb.q_target - sent.q))) > SERVO_END_TOLERANCE_RAD
            and fb.timestamp_ms < self._servo_sent_ms + (sent.t_s + SERVO_END_GRACE_S) * 1000.0
        ):
            return  # the controller still runs the last target (it took it up late): servoStop would cut it
        if sent is not None:
            self._servo_sent = None
        if not self._servo_queue:
            if sent is not None:  # the stream ended: leave servo mode at the last target
                self._servo_busy = True
                asyncio.get_running_loop().create_task(self._servo_stop(), name=f"ur-servo-stop-{self.host}")
            return
        item = self._servo_queue.popleft()
        self._servo_sent, self._servo_sent_ms = item, fb.timestamp_ms
        # as a Dobot's CurrentCommandId: the target the controller is executing now
        self.current_command_id = max(self.current_command_id, item.id)
        self._servo_busy = True
        asyncio.get_running_loop().create_task(self._servo_send(item), name=f"ur-servo-{self.host}")

    async def _servo_send(self, item: _Servo) -> None:
        try:
            ok, stamp_s = await self._call(
                "servoJ", lambda: self._io.servo(item.q.tolist(), item.t_s, SERVO_LOOKAHEAD_S, SERVO_GAIN)
            )
            if not ok:
                log.warning("UR %s refused servoJ %d", self.host, item.id)
                self._abandon_motion()
            elif self._servo_sent is item:
                # its t runs from when it reached the controller (its clock then, not the older packet
                # this loop last handled), not from when it was queued here: a call held up by a busy
                # host would otherwise have the next target follow it too soon, and the script's servo
                # thread take up only the newer of the two (a step in speed)
                self._servo_sent_ms = max(self._servo_sent_ms, round(stamp_s * 1000.0))
        except RobotCommunicationError as exc:
            log.warning("servoJ %d not sent: %s", item.id, exc)
            self._abandon_motion()
        finally:
            self._servo_busy = False

    async def _servo_stop(self) -> None:
        try:
            await self._call("servoStop", lambda: self._io.control_call("servoStop", STOP_DECEL_RAD_S2))
        except RobotCommunicationError as exc:
            log.warning("servoStop failed: %s", exc)
        finally:
            self._servo_busy = False

    async def _settle_servo(self) -> None:
        """A move after a servo stream waits for the stream's servoStop (the script's servo thread
        would otherwise fight the move thread)."""
        while self._servo_busy or self._servo_sent is not None or self._servo_queue:
            await self.next_feedback()

    async def digital_output(
        self, index: int, on: bool, tool: bool = False, queued: bool = True
    ) -> int | None:
        self._check_link("digital output")
        if queued:
            while self._moving() or self._servo_busy:  # after the motion already sent, like a queue
                await self.next_feedback()
        if not 1 <= index <= (2 if tool else 8):
            raise InvalidInputError(
                f"UR {'tool' if tool else 'standard'} digital output {index} does not exist"
            )
        await self._outputs.set(index - 1, bool(on), tool)
        cid = self._new_id()
        bit = (16 if tool else 0) + index - 1
        await self.wait_controller(
            lambda f: bool((f.digital_outputs >> bit) & 1) == bool(on), self.request_timeout_s
        )
        self.current_command_id = max(self.current_command_id, cid)
        return cid
