"""Asyncio client for a Dobot V4 controller (real or simulated): the I/O around
:mod:`services.dobot`.

- Dashboard (29999): requests may be in flight together; replies are matched to
  requests by their echo, so a late reply after a timeout never shifts the
  others. Every request has a timeout.
- Feedback (30004): a background reader frames the 1440-byte packets
  (resynchronising after garbage) and keeps the newest decoded state; waiters
  are woken per packet; listeners get every packet.
- Connection loss fails pending requests at once; the next request reconnects
  with capped, jittered backoff and a bounded number of attempts.
- Motion completion is awaited from the feedback stream (CurrentCommandId and
  RobotMode) with a deadline — never a sleep loop. Every deadline about the arm is
  on the controller's clock (the packets' TimeStamp), with a generous wall-clock
  guard only against a controller whose clock has stopped.

The API is SI (radians, metres, 4x4 transforms); degrees and millimetres exist
only in the strings this module sends and parses.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import logging
import random
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from services import dobot
from services.common.errors import (
    ControllerError,
    EmergencyStopError,
    ExecutionError,
    RobotCommunicationError,
    TrajectoryExecutionError,
)
from services.common.frames import dobot_pose_to_transform, finite_vector, transform_to_dobot_pose
from services.common.settings import ReconnectSettings
from services.dobot import RobotMode

log = logging.getLogger("pickplace.robot.client")


def _deg(v_rad: np.ndarray) -> list[float]:
    """Radians → degrees, as the plain floats the command codec formats."""
    return np.rad2deg(v_rad).tolist()


def _pose(T: np.ndarray) -> list[float]:
    """A transform → the controller's pose (mm, degrees), as plain floats."""
    return transform_to_dobot_pose(T).tolist()


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
    def from_record(cls, rec: np.ndarray, received_ns: int) -> FeedbackState:
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
    def in_error(self) -> bool:
        return self.robot_mode in (RobotMode.ERROR, RobotMode.COLLISION)


@dataclass
class _Pending:
    command: str
    future: asyncio.Future[dobot.Reply]


class _ControllerDeadline(Exception):
    """A wait's deadline passed on the controller's clock (turned into TimeoutError)."""


# The wall-clock guard of a controller-clock wait: only for a controller whose clock stops while its
# packets still come (a dead link is caught sooner, by the feedback timeout). Generous on purpose: a
# simulator on a loaded machine legitimately runs its clock many times slower than the wall.
WALL_GUARD_MIN_S = 30.0
WALL_GUARD_FACTOR = 20.0


def _wall_guard_s(controller_timeout_s: float) -> float:
    return WALL_GUARD_MIN_S + WALL_GUARD_FACTOR * controller_timeout_s


def _backoff(attempt: int, rs: ReconnectSettings) -> float:
    """Capped exponential backoff with full jitter."""
    cap = min(rs.max_delay_s, rs.base_delay_s * (2**attempt))
    return random.uniform(cap / 2, cap)


class DobotClient:
    def __init__(
        self,
        host: str,
        dashboard_port: int = 29999,
        feedback_port: int = 30004,
        *,
        request_timeout_s: float = 2.0,
        connect_timeout_s: float = 2.0,
        feedback_timeout_s: float = 1.0,
        reconnect: ReconnectSettings | None = None,
    ):
        self.host = host
        self.dashboard_port = dashboard_port
        self.feedback_port = feedback_port
        self.request_timeout_s = request_timeout_s
        self.connect_timeout_s = connect_timeout_s
        self.feedback_timeout_s = feedback_timeout_s
        self.reconnect = reconnect or ReconnectSettings()
        self.state = ClientState.IDLE
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._rx_task: asyncio.Task[None] | None = None
        self._fb_task: asyncio.Task[None] | None = None
        self._pending: list[_Pending] = []
        self._connect_lock = asyncio.Lock()
        self._feedback: FeedbackState | None = None
        self._fb_event = asyncio.Event()
        self._fb_error: RobotCommunicationError | None = None
        self._listeners: list[Callable[[FeedbackState], None]] = []
        self.packets_received = 0
        self.framer_resyncs = 0

    # ------------------------------------------------------------------ lifecycle
    async def __aenter__(self) -> DobotClient:
        await self.connect()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def connect(self) -> None:
        if self.state is ClientState.CLOSED:
            raise RuntimeError("client is closed")
        await self._ensure_dashboard()
        if self._fb_task is None:
            await self._wait_first_feedback()

    async def _wait_first_feedback(self) -> None:
        self._fb_error = None
        self._fb_task = asyncio.create_task(self._feedback_loop(), name=f"dobot-feedback-{self.host}")
        await self.wait_feedback(lambda fb: True, self.connect_timeout_s + self.feedback_timeout_s)

    async def close(self) -> None:
        self.state = ClientState.CLOSED
        for task in (self._rx_task, self._fb_task):
            if task is not None:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
        self._rx_task = self._fb_task = None
        self._drop_dashboard(RobotCommunicationError("client closed"))

    async def _open(self, port: int) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        last: Exception | None = None
        attempts = self.reconnect.max_attempts
        for attempt in range(attempts):
            if self.state is ClientState.CLOSED:
                raise RobotCommunicationError("client closed")
            try:
                async with asyncio.timeout(self.connect_timeout_s):
                    return await asyncio.open_connection(self.host, port)
            except (OSError, TimeoutError) as exc:
                last = exc
                if attempt + 1 < attempts:
                    delay = _backoff(attempt, self.reconnect)
                    log.warning(
                        "connect %s:%d failed (%s); retry %d/%d in %.2fs",
                        self.host,
                        port,
                        exc,
                        attempt + 1,
                        attempts - 1,
                        delay,
                    )
                    await asyncio.sleep(delay)
        raise RobotCommunicationError(
            f"cannot reach the robot controller at {self.host}:{port} after {attempts} attempts: {last}"
        )

    async def _ensure_dashboard(self) -> None:
        if self._writer is not None and not self._writer.is_closing():
            return
        async with self._connect_lock:
            if self._writer is not None and not self._writer.is_closing():
                return
            self.state = ClientState.CONNECTING
            try:
                self._reader, self._writer = await self._open(self.dashboard_port)
            except RobotCommunicationError:
                self.state = ClientState.DISCONNECTED
                raise
            self._rx_task = asyncio.create_task(
                self._dashboard_loop(self._reader), name=f"dobot-dashboard-{self.host}"
            )
            self.state = ClientState.CONNECTED
            log.info("connected to Dobot dashboard %s:%d", self.host, self.dashboard_port)

    def _drop_dashboard(self, error: RobotCommunicationError) -> None:
        if self._writer is not None:
            with contextlib.suppress(Exception):
                self._writer.close()
        self._writer = None
        self._reader = None
        pending, self._pending = self._pending, []
        for p in pending:
            if not p.future.done():
                p.future.set_exception(error)
        if self.state is not ClientState.CLOSED:
            self.state = ClientState.DISCONNECTED

    async def _dashboard_loop(self, reader: asyncio.StreamReader) -> None:
        parser = dobot.ReplyParser()
        reason = "connection closed by the controller"
        try:
            while True:
                data = await reader.read(65536)
                if not data:
                    break
                for item in parser.feed(data):
                    self._dispatch_reply(item)
        except asyncio.CancelledError:
            raise
        except OSError as exc:
            reason = f"connection error: {exc}"
        if self._reader is reader:
            log.warning("Dobot dashboard %s:%d lost: %s", self.host, self.dashboard_port, reason)
            self._drop_dashboard(RobotCommunicationError(f"dashboard connection lost ({reason})"))

    def _dispatch_reply(self, item: dobot.Reply | dobot.Unparseable) -> None:
        if isinstance(item, dobot.Unparseable):
            log.warning("unparseable reply from controller (%s): %r", item.reason, item.text)
            if self._pending:
                p = self._pending.pop(0)
                if not p.future.done():
                    p.future.set_exception(
                        RobotCommunicationError(
                            f"controller sent an unparseable reply to {p.command!r}: {item.reason}: {item.text!r}"
                        )
                    )
            return
        echo = item.echo.replace(" ", "")
        for i, p in enumerate(self._pending):
            if p.command.replace(" ", "") == echo:
                del self._pending[i]
                if not p.future.done():
                    p.future.set_result(item)
                return
        # A firmware that echoes differently (case, number formats): fall back to FIFO by name.
        for i, p in enumerate(self._pending):
            if p.command.split("(", 1)[0].lower() == item.command_name.lower():
                del self._pending[i]
                if not p.future.done():
                    p.future.set_result(item)
                return
        # a request cancelled or timed out before its reply came (e.g. a guarded move stopping)
        log.debug("reply matched no pending request: %r", item.raw)

    # ------------------------------------------------------------------ feedback
    async def _feedback_loop(self) -> None:
        attempt = 0
        while self.state is not ClientState.CLOSED:
            try:
                reader, writer = await self._open(self.feedback_port)
            except RobotCommunicationError as exc:
                self._fb_error = exc
                self._fb_event.set()
                self._fb_event = asyncio.Event()
                return
            attempt = 0
            framer = dobot.FeedbackFramer()
            try:
                while True:
                    async with asyncio.timeout(max(self.feedback_timeout_s, 0.05) * 5):
                        data = await reader.read(65536)
                    if not data:
                        raise ConnectionError("feedback connection closed by the controller")
                    now = time.time_ns()
                    records = framer.feed(data)
                    self.framer_resyncs = framer.resyncs
                    if records:
                        # several packets in one read: every listener sees each, waiters the newest
                        for rec in records:
                            fb = FeedbackState.from_record(rec, now)
                            self.packets_received += 1
                            for cb in list(self._listeners):
                                try:
                                    cb(fb)
                                except Exception:
                                    log.exception("feedback listener failed")
                        self._feedback = fb
                        ev, self._fb_event = self._fb_event, asyncio.Event()
                        ev.set()
            except asyncio.CancelledError:
                with contextlib.suppress(Exception):
                    writer.close()
                raise
            except (OSError, TimeoutError, ConnectionError) as exc:
                with contextlib.suppress(Exception):
                    writer.close()
                log.warning(
                    "Dobot feedback %s:%d lost (%s); reconnecting", self.host, self.feedback_port, exc
                )
                attempt += 1
                await asyncio.sleep(_backoff(attempt, self.reconnect))

    @property
    def feedback(self) -> FeedbackState | None:
        return self._feedback

    def add_listener(self, callback: Callable[[FeedbackState], None]) -> None:
        self._listeners.append(callback)

    def remove_listener(self, callback: Callable[[FeedbackState], None]) -> None:
        with contextlib.suppress(ValueError):
            self._listeners.remove(callback)

    async def next_feedback(self, timeout_s: float | None = None) -> FeedbackState:
        """Wait for the next packet (RobotCommunicationError when none arrives in time)."""
        timeout_s = self.feedback_timeout_s if timeout_s is None else timeout_s
        if self._fb_error is not None:
            raise self._fb_error
        ev = self._fb_event
        try:
            async with asyncio.timeout(timeout_s):
                await ev.wait()
        except TimeoutError:
            raise RobotCommunicationError(
                f"no feedback from {self.host}:{self.feedback_port} for {timeout_s:.2f}s"
            ) from None
        if self._fb_error is not None:
            raise self._fb_error
        assert self._feedback is not None
        return self._feedback

    async def wait_feedback(
        self, predicate: Callable[[FeedbackState], bool], timeout_s: float
    ) -> FeedbackState:
        """Wait until a packet satisfies ``predicate``, ``timeout_s`` of controller time at most
        (:meth:`wait_controller`)."""
        return await self.wait_controller(predicate, timeout_s)

    async def wait_controller(
        self,
        predicate: Callable[[FeedbackState], bool],
        controller_timeout_s: float,
        *,
        since_ms: int | None = None,
        wall_guard_s: float | None = None,
    ) -> FeedbackState:
        """Wait until a packet satisfies ``predicate``; the deadline is on the controller's clock (the
        packets' TimeStamp, from ``since_ms`` or the newest packet's stamp), so a busy machine or a
        simulator at N× waits exactly as long as the arm does.

        TimeoutError when a packet stamped past the deadline still fails ``predicate``;
        RobotCommunicationError when the stream goes silent, or when its clock does not reach the
        deadline within ``wall_guard_s`` of wall time (a frozen controller, not a slow one)."""
        fb = self._feedback if self._feedback is not None else await self.next_feedback()
        start_ms = fb.timestamp_ms if since_ms is None else since_ms
        deadline_ms = start_ms + controller_timeout_s * 1000.0
        guard = wall_guard_s if wall_guard_s is not None else _wall_guard_s(controller_timeout_s)
        try:
            async with asyncio.timeout(guard):
                while not predicate(fb):
                    if fb.timestamp_ms >= deadline_ms:
                        raise _ControllerDeadline
                    fb = await self.next_feedback(self.feedback_timeout_s)
        except _ControllerDeadline:
            raise TimeoutError(
                f"feedback condition not met within {controller_timeout_s:.2f}s of controller time"
            ) from None
        except TimeoutError:
            raise RobotCommunicationError(
                f"the controller clock at {self.host}:{self.feedback_port} did not advance "
                f"{controller_timeout_s:.2f}s within {guard:.0f}s of wall time"
            ) from None
        return fb

    async def wait_controller_time(self, duration_s: float, since_ms: int | None = None) -> FeedbackState:
        """Wait until the controller's clock has run ``duration_s`` past ``since_ms`` (default: the
        newest packet's stamp): a physical delay the controller cannot report (jaw travel), timed as
        the arm experiences it. Returns the first packet stamped at or after that instant."""
        fb = self._feedback if self._feedback is not None else await self.next_feedback()
        until_ms = (fb.timestamp_ms if since_ms is None else since_ms) + duration_s * 1000.0
        return await self.wait_controller(
            lambda f: f.timestamp_ms >= until_ms, duration_s + 1.0, since_ms=since_ms
        )

    # ------------------------------------------------------------------ requests
    async def raw_request(self, command: str, timeout_s: float | None = None) -> dobot.Reply:
        """Send one command; return its reply whatever the ErrorID."""
        await self._ensure_dashboard()
        assert self._writer is not None
        fut: asyncio.Future[dobot.Reply] = asyncio.get_running_loop().create_future()
        pending = _Pending(command, fut)
        self._pending.append(pending)
        try:
            self._writer.write(command.encode())
            async with asyncio.timeout(self.request_timeout_s if timeout_s is None else timeout_s):
                return await fut
        except TimeoutError:
            raise RobotCommunicationError(
                f"no reply to {command!r} from {self.host}:{self.dashboard_port} within "
                f"{self.request_timeout_s if timeout_s is None else timeout_s:.2f}s"
            ) from None
        except OSError as exc:
            self._drop_dashboard(RobotCommunicationError(f"send failed: {exc}"))
            raise RobotCommunicationError(f"sending {command!r} failed: {exc}") from exc
        finally:
            with contextlib.suppress(ValueError):
                self._pending.remove(pending)

    async def request(self, command: str, timeout_s: float | None = None) -> dobot.Reply:
        """Send one command; raise ControllerError (or EmergencyStopError) unless ErrorID is 0."""
        reply = await self.raw_request(command, timeout_s)
        if reply.error_id == dobot.ErrorID.ESTOP:
            raise EmergencyStopError(f"{command} refused: {dobot.describe_error_id(reply.error_id)}")
        if reply.error_id != 0:
            raise ControllerError(
                f"{command} refused with ErrorID {reply.error_id}: {dobot.describe_error_id(reply.error_id)}",
                error_id=reply.error_id,
            )
        return reply

    # ------------------------------------------------------------------ commands (SI)
    async def enable(self, load_kg: float = 0.0) -> None:
        await self.request(dobot.enable_robot(load_kg))

    async def disable(self) -> None:
        await self.request("DisableRobot()")

    async def clear_error(self) -> None:
        await self.request("ClearError()")

    async def robot_mode(self) -> int:
        return int((await self.request("RobotMode()")).floats()[0])

    async def error_ids(self) -> list[int]:
        reply = await self.request("GetErrorID()")
        return dobot.parse_error_ids(reply.values_text)

    async def current_command_id(self) -> int:
        return int((await self.request("GetCurrentCommandID()")).floats()[0])

    async def get_angles(self) -> np.ndarray:
        return np.deg2rad((await self.request("GetAngle()")).floats())

    async def get_pose(self) -> np.ndarray:
        return dobot_pose_to_transform((await self.request("GetPose()")).floats())

    async def speed_factor(self, ratio: int) -> None:
        await self.request(dobot.speed_factor(ratio))

    async def acceleration_ratio(self, ratio: int) -> None:
        """AccJ and AccL at once: the acceleration percentage of MovJ / MovL without their own ``a=``."""
        for cmd in dobot.acceleration_ratios(ratio):
            await self.request(cmd)

    async def stop(self) -> None:
        await self.request("Stop()")

    async def emergency_stop(self, press: bool = True) -> None:
        # e-stop must never be refused by our own checks: raw send, then inspect
        reply = await self.raw_request(dobot.emergency_stop(press))
        if reply.error_id != 0:
            raise ControllerError(
                f"EmergencyStop refused with ErrorID {reply.error_id}", error_id=reply.error_id
            )

    async def positive_kin(self, q: ArrayLike) -> np.ndarray:
        q_rad = finite_vector(q, 6, "joints")
        return dobot_pose_to_transform((await self.request(dobot.positive_kin(_deg(q_rad)))).floats())

    async def inverse_kin(self, T: np.ndarray, joint_near: ArrayLike | None = None) -> np.ndarray:
        near = None if joint_near is None else _deg(finite_vector(joint_near, 6, "joint_near"))
        reply = await self.request(dobot.inverse_kin(_pose(T), near))
        return np.deg2rad(reply.floats())

    async def digital_output(
        self, index: int, on: bool, tool: bool = False, queued: bool = True
    ) -> int | None:
        if queued:
            return (await self.request(dobot.digital_output(index, on, tool))).result_id
        name = "ToolDOInstant" if tool else "DOInstant"
        await self.request(dobot.command(name, dobot.fmt_int(index), "1" if on else "0"))
        return None

    async def digital_input(self, index: int, tool: bool = False) -> bool:
        reply = await self.request(dobot.command("ToolDI" if tool else "DI", dobot.fmt_int(index)))
        return bool(int(reply.floats()[0]))

    async def mov_j(
        self, q: ArrayLike, a: int | None = None, v: int | None = None, cp: int | None = None
    ) -> int | None:
        q_rad = finite_vector(q, 6, "joint target")
        return (await self.request(dobot.mov_j_joint(_deg(q_rad), a, v, cp))).result_id

    async def mov_j_pose(self, T: np.ndarray, a: int | None = None, v: int | None = None) -> int | None:
        return (await self.request(dobot.mov_j_pose(_pose(T), a, v))).result_id

    async def mov_l(self, q: ArrayLike, a: int | None = None, v: int | None = None) -> int | None:
        q_rad = finite_vector(q, 6, "joint target")
        return (await self.request(dobot.mov_l_joint(_deg(q_rad), a, v))).result_id

    async def mov_l_pose(
        self, T: np.ndarray, a: int | None = None, v: int | None = None, speed_m_s: float | None = None
    ) -> int | None:
        speed = None if speed_m_s is None else max(1, round(speed_m_s * 1000))
        return (await self.request(dobot.mov_l_pose(_pose(T), a, v, speed))).result_id

    async def servo_j(self, q: ArrayLike, t_s: float) -> int | None:
        q_rad = finite_vector(q, 6, "servo target")
        return (await self.request(dobot.servo_j(_deg(q_rad), t_s))).result_id

    async def rel_mov_l_tool(
        self, offset_m_rad: ArrayLike, a: int | None = None, v: int | None = None
    ) -> int | None:
        o = finite_vector(offset_m_rad, 6, "offset")
        mm_deg = [*(o[:3] * 1000.0).tolist(), *_deg(o[3:])]
        return (await self.request(dobot.rel_mov_l_tool(mm_deg, a, v))).result_id

    async def rel_mov_j_tool(
        self, offset_m_rad: ArrayLike, a: int | None = None, v: int | None = None
    ) -> int | None:
        o = finite_vector(offset_m_rad, 6, "offset")
        mm_deg = [*(o[:3] * 1000.0).tolist(), *_deg(o[3:])]
        return (await self.request(dobot.rel_mov_j_tool(mm_deg, a, v))).result_id

    async def rel_joint_mov_j(self, dq: ArrayLike, a: int | None = None, v: int | None = None) -> int | None:
        d = finite_vector(dq, 6, "joint offsets")
        return (await self.request(dobot.rel_joint_mov_j(_deg(d), a, v))).result_id

    # ------------------------------------------------------------------ completion
    async def describe_alarms(self) -> tuple[list[int], str]:
        try:
            ids = await self.error_ids()
        except Exception as exc:  # the alarm itself matters more than why we couldn't read it
            return [], f"(GetErrorID failed: {exc})"
        return ids, ", ".join(f"{i}: {dobot.describe_alarm(i)}" for i in ids) or "no alarm IDs reported"

    async def wait_motion_done(self, result_id: int | None, timeout_s: float) -> FeedbackState:
        """Wait until the queue command ``result_id`` finished and the arm is idle; ``timeout_s`` is
        controller time (the packets' TimeStamp).

        Raises ControllerError when the controller alarms (with its alarm IDs),
        EmergencyStopError on e-stop, ExecutionError if the arm is disabled, and
        TrajectoryExecutionError when the deadline passes on the controller's clock, and
        RobotCommunicationError when that clock stalls (see :meth:`wait_controller`).
        """
        fb = self._feedback if self._feedback is not None else await self.next_feedback()
        deadline_ms = fb.timestamp_ms + timeout_s * 1000.0
        seen_running = False
        try:
            async with asyncio.timeout(_wall_guard_s(timeout_s)):
                while True:
                    fb = await self.next_feedback(self.feedback_timeout_s)
                    if fb.estop:
                        raise EmergencyStopError("emergency stop is active; motion aborted")
                    if fb.in_error:
                        ids, text = await self.describe_alarms()
                        raise ControllerError(
                            f"controller alarm during motion {result_id}: {text}", alarms=tuple(ids)
                        )
                    if fb.robot_mode == RobotMode.DISABLED:
                        raise ExecutionError(f"robot was disabled during motion {result_id}")
                    if fb.robot_mode == RobotMode.RUNNING:
                        seen_running = True
                    if fb.robot_mode == RobotMode.ENABLE:
                        if result_id is not None and fb.current_command_id >= result_id:
                            return fb
                        if result_id is None and seen_running:
                            return fb
                    if fb.timestamp_ms >= deadline_ms:
                        raise TrajectoryExecutionError(
                            f"motion {result_id} not finished within {timeout_s:.1f}s of controller time "
                            f"(mode {RobotMode.name_of(fb.robot_mode)}, "
                            f"current command {fb.current_command_id})"
                        )
        except TimeoutError:
            raise RobotCommunicationError(
                f"the controller clock at {self.host}:{self.feedback_port} did not advance "
                f"{timeout_s:.1f}s within {_wall_guard_s(timeout_s):.0f}s of wall time "
                f"(motion {result_id})"
            ) from None
