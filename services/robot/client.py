"""Asyncio client for a Dobot V4 controller (real or simulated): the I/O around
:mod:`services.dobot`.

- Dashboard (29999): requests may be in flight together; replies are matched to
  requests by their echo, so a late reply after a timeout never shifts the
  others. Every request has a timeout.
- Dashboard replies are matched strictly, by echo and in order: a request that times out leaves a
  tombstone, so its late reply is discarded and never handed to a later command.
- Feedback (30004): a background reader frames the 1440-byte packets
  (resynchronising after garbage), drops and counts every packet whose values are not finite or
  plausible or whose clock runs backwards (:func:`dobot.feedback_fault`), and keeps the newest sound
  state; waiters are woken per packet; listeners get every sound packet. A run of bad packets is a
  link fault. No NaN state ever leaves this module.
- The link always comes back: the feedback reader reconnects forever (capped, jittered backoff) while
  the client lives, and :attr:`DobotClient.link` says whether it is up, down or reconnecting. A loss
  fails every feedback waiter with RobotCommunicationError; a loss while the arm moves also owes the
  controller a Stop, sent the moment the dashboard is reachable and before any motion command is let
  through again; the cut motion is never resent. Requests reconnect the dashboard with a bounded
  number of attempts, so a request fails in bounded time.
- Motion completion is awaited from the feedback stream (CurrentCommandId and
  RobotMode) with a deadline — never a sleep loop. Every deadline about the arm is
  on the controller's clock (the packets' TimeStamp), with a generous wall-clock
  guard only against a controller whose clock has stopped.

The API is SI (radians, metres, 4x4 transforms): the typed commands are
:class:`services.robot.commands.DobotCommands`, the states it reports
:mod:`services.robot.feedback`; degrees and millimetres exist only in the strings sent and parsed.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import re
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from services import dobot
from services.common.errors import (
    ContactAlarmError,
    ControllerError,
    EmergencyStopError,
    ExecutionError,
    RobotCommunicationError,
    TrajectoryExecutionError,
)
from services.common.settings import ReconnectSettings
from services.dobot import RobotMode
from services.robot.commands import DobotCommands, raise_for_reply
from services.robot.feedback import ClientState, FeedbackState, LinkEvent, LinkEventKind, LinkState
from services.robot.priority_lane import PriorityLane

log = logging.getLogger("pickplace.robot.client")

# A run of this many bad packets (8 ms each: 200 ms) is a link fault, not noise.
BAD_FEEDBACK_RUN = 25
# A request that timed out leaves a tombstone for its late reply; beyond this many the oldest go.
MAX_TOMBSTONES = 64
LINK_EVENTS_KEPT = 256


def _num_key(token: str) -> str:
    try:
        return repr(round(float(token), 6))
    except ValueError:
        return token.lower()


def echo_key(text: str) -> str:
    """A command's identity as its echo shows it: case, spaces and number formats do not matter
    (``MovJ(joint={1,2.50})`` == ``movj(joint = {1.000, 2.5})``), every value does."""
    compact = text.replace(" ", "").replace("\t", "")
    return "".join(_num_key(tok) for tok in _ECHO_TOKENS.split(compact))


_ECHO_TOKENS = re.compile(r"([(){}\[\],=])")


@dataclass
class _Pending:
    command: str
    future: asyncio.Future[dobot.Reply]
    key: str = ""
    abandoned: bool = False  # timed out or cancelled: its reply, when it comes, is discarded


class _Wake:
    """What feedback waiters wait on: set by the next sound packet, or by a link loss (``error``)."""

    __slots__ = ("error", "event")

    def __init__(self) -> None:
        self.event = asyncio.Event()
        self.error: RobotCommunicationError | None = None


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


class DobotClient(DobotCommands):
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
        bad_feedback_run: int = BAD_FEEDBACK_RUN,
    ):
        if bad_feedback_run < 1:
            raise ValueError("bad_feedback_run must be at least 1")
        self.host = host
        self.dashboard_port = dashboard_port
        self.feedback_port = feedback_port
        self.request_timeout_s = request_timeout_s
        self.connect_timeout_s = connect_timeout_s
        self.feedback_timeout_s = feedback_timeout_s
        self.reconnect = reconnect or ReconnectSettings()
        self.bad_feedback_run = bad_feedback_run
        self.state = ClientState.IDLE
        self.link = LinkState.DOWN
        self.link_epoch = 0  # +1 at every loss of either socket
        self.link_events: deque[LinkEvent] = deque(maxlen=LINK_EVENTS_KEPT)
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._rx_task: asyncio.Task[None] | None = None
        self._fb_task: asyncio.Task[None] | None = None
        self._stop_task: asyncio.Task[None] | None = None
        # the e-stop's own connection (services.robot.priority_lane): never behind other requests
        self.estop_lane = PriorityLane(host, dashboard_port, connect_timeout_s, request_timeout_s)
        self._pending: list[_Pending] = []
        self._connect_lock = asyncio.Lock()
        self._feedback: FeedbackState | None = None
        self._wake = _Wake()
        self._listeners: list[Callable[[FeedbackState], None]] = []
        # motion bookkeeping for a loss: the newest queue ID accepted, the newest one a loss cut off,
        # and whether the controller is owed a Stop (motion commands are refused until it is sent)
        self._last_queued_id: int | None = None
        self._cut_upto_id = 0
        self.stop_owed = False
        self.packets_received = 0  # sound packets
        self.framer_resyncs = 0
        self.feedback_rejected = 0  # packets dropped as not finite / implausible / clock backwards
        self.feedback_rejections: Counter[str] = Counter()  # by reason
        self.link_faults = 0  # runs of bad packets that cut the link
        self.feedback_connect_failures = 0
        self.late_replies_discarded = 0  # replies to requests that had timed out
        self.unmatched_replies = 0  # replies whose echo matched no request

    # ------------------------------------------------------------------ lifecycle
    async def __aenter__(self) -> DobotClient:
        await self.connect()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def connect(self) -> None:
        """Open the dashboard (bounded attempts) and the feedback stream, and wait for its first sound
        packet. The feedback reader then keeps the link up for as long as the client lives."""
        if self.state is ClientState.CLOSED:
            raise RuntimeError("client is closed")
        await self._ensure_dashboard()
        await self.estop_lane.open()
        if self._fb_task is None or self._fb_task.done():
            self._fb_task = asyncio.create_task(self._feedback_loop(), name=f"dobot-feedback-{self.host}")
        if self.link is not LinkState.UP:
            await self._wait_link_up(self.connect_timeout_s + self.feedback_timeout_s)

    async def _wait_link_up(self, timeout_s: float) -> None:
        try:
            async with asyncio.timeout(timeout_s):
                while self.link is not LinkState.UP:
                    with contextlib.suppress(RobotCommunicationError):
                        await self.next_feedback(timeout_s)
        except TimeoutError:
            raise RobotCommunicationError(
                f"no sound feedback from {self.host}:{self.feedback_port} within {timeout_s:.2f}s"
            ) from None

    async def close(self) -> None:
        self.state = ClientState.CLOSED
        self.link = LinkState.DOWN
        for task in (self._rx_task, self._fb_task, self._stop_task):
            if task is not None:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
        self._rx_task = self._fb_task = self._stop_task = None
        await self.estop_lane.close()
        self._drop_dashboard(RobotCommunicationError("client closed"))
        self._fail_waiters(RobotCommunicationError("client closed"))

    async def _open(
        self, port: int, attempts: int | None = None
    ) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        last: Exception | None = None
        attempts = self.reconnect.max_attempts if attempts is None else attempts
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

    async def _ensure_dashboard(self, attempts: int | None = None) -> None:
        if self._writer is not None and not self._writer.is_closing():
            return
        async with self._connect_lock:
            if self._writer is not None and not self._writer.is_closing():
                return
            self.state = ClientState.CONNECTING
            try:
                self._reader, self._writer = await self._open(self.dashboard_port, attempts)
            except RobotCommunicationError:
                if self.state is not ClientState.CLOSED:
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
            self._link_lost(f"dashboard connection lost ({reason})")
            self._drop_dashboard(RobotCommunicationError(f"dashboard connection lost ({reason})"))

    def _dispatch_reply(self, item: dobot.Reply | dobot.Unparseable) -> None:
        """Replies come in the order the commands went out: each belongs to the oldest request whose
        echo it carries. Requests before that one got no reply and never will (failed: the stream is
        resynchronised); a reply to an abandoned (timed-out) request is discarded; a reply matching no
        request is discarded. A reply is never handed to a command it does not echo."""
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
        key = echo_key(item.echo)
        for i, p in enumerate(self._pending):
            if p.key != key:
                continue
            skipped, self._pending = self._pending[:i], self._pending[i + 1 :]
            for s in skipped:
                if not s.future.done():
                    s.future.set_exception(
                        RobotCommunicationError(
                            f"no reply to {s.command!r}: the controller answered a later command "
                            f"({item.echo!r}) first; stream resynchronised"
                        )
                    )
            if p.abandoned or p.future.done():
                self.late_replies_discarded += 1
                log.info("discarded the late reply to a timed-out request: %r", item.raw)
            else:
                p.future.set_result(item)
            return
        self.unmatched_replies += 1
        log.warning("reply matched no request, discarded: %r", item.raw)

    # ------------------------------------------------------------------ link
    def _motion_in_progress(self) -> bool:
        """Whether the arm may be moving on our commands: a queue command awaiting its reply, the
        controller running, or a queue ID accepted that the feedback has not shown finished."""
        if any(p.key.split("(", 1)[0] in dobot.QUEUE_COMMANDS and not p.abandoned for p in self._pending):
            return True
        fb = self._feedback
        if fb is not None and fb.robot_mode in (RobotMode.RUNNING, RobotMode.PAUSE):
            return True
        last = self._last_queued_id
        return last is not None and (fb is None or fb.current_command_id < last)

    def _fail_waiters(self, error: RobotCommunicationError) -> None:
        wake, self._wake = self._wake, _Wake()
        wake.error = error
        wake.event.set()

    def _link_lost(self, reason: str) -> None:
        """Either socket is gone (or the feedback turned bad): a new epoch, every waiter failed, and
        when the arm may be moving, a Stop owed before any motion command is let through."""
        if self.state is ClientState.CLOSED:
            return
        self.link_epoch += 1
        stamp = None if self._feedback is None else self._feedback.timestamp_ms
        self.link_events.append(LinkEvent(LinkEventKind.LOST, self.link_epoch, stamp, reason))
        if self._motion_in_progress():
            self.stop_owed = True
            self._cut_upto_id = max(self._cut_upto_id, self._last_queued_id or 0)
            if self._stop_task is None or self._stop_task.done():
                self._stop_task = asyncio.create_task(self._deliver_stop(), name=f"dobot-stop-{self.host}")
        self._fail_waiters(RobotCommunicationError(f"robot link lost: {reason}"))

    async def _deliver_stop(self) -> None:
        """Send the owed Stop as soon as the dashboard answers: one connect attempt at a time, capped
        jittered backoff between them, for as long as the client lives."""
        attempt = 0
        while self.stop_owed and self.state is not ClientState.CLOSED:
            try:
                await self._ensure_dashboard(attempts=1)
                reply = await self.raw_request("Stop()")
            except RobotCommunicationError as exc:
                delay = _backoff(min(attempt, 16), self.reconnect)
                attempt += 1
                log.debug("owed Stop not delivered yet (%s); retry in %.2fs", exc, delay)
                await asyncio.sleep(delay)
                continue
            if reply.error_id != 0:  # e.g. e-stop active: the arm is halted anyway
                log.warning("Stop after a link loss answered ErrorID %d", reply.error_id)
            self.stop_owed = False
            self._last_queued_id = None
            stamp = None if self._feedback is None else self._feedback.timestamp_ms
            self.link_events.append(
                LinkEvent(LinkEventKind.STOP_SENT, self.link_epoch, stamp, "motion cut by a link loss")
            )
            log.warning("sent Stop to %s after a link loss during motion", self.host)

    # ------------------------------------------------------------------ feedback
    async def _feedback_loop(self) -> None:
        """Connect, read, and on any loss reconnect — forever, with capped jittered backoff."""
        attempt = 0
        while self.state is not ClientState.CLOSED:
            try:
                async with asyncio.timeout(self.connect_timeout_s):
                    reader, writer = await asyncio.open_connection(self.host, self.feedback_port)
            except (OSError, TimeoutError) as exc:
                self.feedback_connect_failures += 1
                delay = _backoff(min(attempt, 16), self.reconnect)
                if attempt % 10 == 0:
                    log.warning(
                        "Dobot feedback %s:%d unreachable (%s); retrying every ≤%.1fs",
                        self.host,
                        self.feedback_port,
                        exc,
                        self.reconnect.max_delay_s,
                    )
                attempt += 1
                await asyncio.sleep(delay)
                continue
            attempt = 0
            try:
                reason = await self._read_feedback(reader)
            finally:
                with contextlib.suppress(Exception):
                    writer.close()
            log.warning("Dobot feedback %s:%d lost (%s); reconnecting", self.host, self.feedback_port, reason)
            if self.link is LinkState.UP:
                self.link = LinkState.RECONNECTING
                self._link_lost(f"feedback {reason}")
            await asyncio.sleep(_backoff(0, self.reconnect))

    async def _read_feedback(self, reader: asyncio.StreamReader) -> str:
        """Read one connection until it fails; returns why it ended."""
        framer = dobot.FeedbackFramer()
        prev_stamp: int | None = None
        bad_run = 0
        try:
            while True:
                async with asyncio.timeout(max(self.feedback_timeout_s, 0.05) * 5):
                    data = await reader.read(65536)
                if not data:
                    return "connection closed by the controller"
                now = time.time_ns()
                records = framer.feed(data)
                self.framer_resyncs = framer.resyncs
                fb: FeedbackState | None = None
                # several packets in one read: every listener sees each, waiters the newest
                for rec in records:
                    try:
                        state = FeedbackState.from_record(rec, now, prev_stamp)
                    except dobot.ProtocolError as exc:
                        self.feedback_rejected += 1
                        self.feedback_rejections[str(exc).split(": ", 1)[-1].split(" (")[0]] += 1
                        bad_run += 1
                        if bad_run >= self.bad_feedback_run:
                            self.link_faults += 1
                            return f"fault: {bad_run} bad packets in a row (last: {exc})"
                        continue
                    bad_run = 0
                    prev_stamp = state.timestamp_ms
                    fb = state
                    self.packets_received += 1
                    if self.link is not LinkState.UP:
                        self.link = LinkState.UP
                        self.link_events.append(
                            LinkEvent(LinkEventKind.RESTORED, self.link_epoch, state.timestamp_ms, "")
                        )
                    for cb in list(self._listeners):
                        try:
                            cb(state)
                        except Exception:  # a listener's bug must not stop the feedback
                            log.exception("feedback listener failed")
                if fb is not None:
                    self._feedback = fb
                    wake, self._wake = self._wake, _Wake()
                    wake.event.set()
        except (OSError, TimeoutError, ConnectionError) as exc:
            return f"connection error: {exc!r}"

    @property
    def feedback(self) -> FeedbackState | None:
        return self._feedback

    def add_listener(self, callback: Callable[[FeedbackState], None]) -> None:
        self._listeners.append(callback)

    def remove_listener(self, callback: Callable[[FeedbackState], None]) -> None:
        with contextlib.suppress(ValueError):
            self._listeners.remove(callback)

    async def next_feedback(self, timeout_s: float | None = None) -> FeedbackState:
        """Wait for the next sound packet. RobotCommunicationError when none arrives in time, or at
        once when the link is lost while waiting."""
        timeout_s = self.feedback_timeout_s if timeout_s is None else timeout_s
        wake = self._wake
        try:
            async with asyncio.timeout(timeout_s):
                await wake.event.wait()
        except TimeoutError:
            raise RobotCommunicationError(
                f"no feedback from {self.host}:{self.feedback_port} for {timeout_s:.2f}s "
                f"(link {self.link.value})"
            ) from None
        if wake.error is not None:
            raise wake.error
        assert self._feedback is not None
        return self._feedback

    def _check_epoch(self, epoch: int, what: str) -> None:
        if self.link_epoch != epoch:
            raise RobotCommunicationError(f"robot link lost during {what}")

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
        epoch = self.link_epoch
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
                    self._check_epoch(epoch, "a controller-clock wait")
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
        """Send one command; return its reply whatever the ErrorID.

        A queue (motion) command is refused while a Stop is owed after a link loss, and fails when the
        link is lost between sending it and its reply: it may have been cut by that Stop, and it is
        never resent."""
        return (await self.raw_requests([command], timeout_s))[0]

    async def raw_requests(
        self, commands: Sequence[str], timeout_s: float | None = None
    ) -> list[dobot.Reply]:
        """Send ``commands`` in one write — pipelined: none waits for another's reply, so the
        controller receives them together — and return their replies in order, whatever the ErrorIDs.
        The rules of :meth:`raw_request` hold for each; the first failure fails the whole call (a
        command whose reply was not awaited then is treated as timed out: its reply is discarded)."""
        if not commands:
            return []
        keys = [echo_key(c) for c in commands]
        queued = [k.split("(", 1)[0] in dobot.QUEUE_COMMANDS for k in keys]
        if any(queued) and self.stop_owed:
            first = commands[queued.index(True)]
            raise RobotCommunicationError(
                f"{first!r} refused: the robot link was lost during motion and the Stop it owes the "
                "controller is not yet delivered"
            )
        await self._ensure_dashboard()
        assert self._writer is not None
        epoch = self.link_epoch
        loop = asyncio.get_running_loop()
        pendings = [_Pending(c, loop.create_future(), k) for c, k in zip(commands, keys, strict=True)]
        self._pending.extend(pendings)
        timeout = self.request_timeout_s if timeout_s is None else timeout_s
        replies: list[dobot.Reply] = []
        try:
            self._writer.write("".join(commands).encode())
            async with asyncio.timeout(timeout):
                for p in pendings:
                    replies.append(await p.future)
        except TimeoutError:
            raise RobotCommunicationError(
                f"no reply to {commands[len(replies)]!r} from {self.host}:{self.dashboard_port} "
                f"within {timeout:.2f}s"
            ) from None
        except OSError as exc:
            self._link_lost(f"dashboard send failed: {exc}")
            self._drop_dashboard(RobotCommunicationError(f"send failed: {exc}"))
            raise RobotCommunicationError(f"sending {commands[0]!r} failed: {exc}") from exc
        finally:
            for p in pendings:
                if not p.future.done():
                    # timed out or cancelled: the controller may still answer; a tombstone takes that reply
                    p.abandoned = True
                    p.future.cancel()
                elif not p.future.cancelled():
                    p.future.exception()  # retrieved (a failure after the first is not raised)
            tombstones = [p for p in self._pending if p.abandoned]
            for old in tombstones[: max(0, len(tombstones) - MAX_TOMBSTONES)]:
                self._pending.remove(old)
        accepted = [r.result_id for r, q in zip(replies, queued, strict=True) if q and r.error_id == 0]
        if accepted:
            ids = [rid for rid in accepted if rid is not None]
            if epoch != self.link_epoch:
                if ids:
                    self._cut_upto_id = max(self._cut_upto_id, *ids)
                raise RobotCommunicationError(
                    f"the robot link was lost while {commands[0]!r}{' and the rest' if len(commands) > 1 else ''} "
                    "was being accepted"
                )
            if ids:
                self._last_queued_id = max(
                    ids if self._last_queued_id is None else [self._last_queued_id, *ids]
                )
        return replies

    async def request(self, command: str, timeout_s: float | None = None) -> dobot.Reply:
        """Send one command; raise ControllerError (or EmergencyStopError) unless ErrorID is 0."""
        reply = await self.raw_request(command, timeout_s)
        raise_for_reply(command, reply)
        return reply

    async def emergency_stop(self, press: bool = True) -> None:
        """Press (or release) the controller's e-stop on the e-stop's own connection, never queued
        behind other requests; the main connection only when that lane cannot reach the controller.
        Never refused by our own checks: sent raw, then the reply inspected."""
        command = dobot.emergency_stop(press)
        try:
            reply = await self.estop_lane.request(command)
        except RobotCommunicationError as exc:
            log.warning("%s; sending the e-stop on the main dashboard connection", exc)
            reply = await self.raw_request(command)
        if reply.error_id != 0:
            raise ControllerError(
                f"EmergencyStop refused with ErrorID {reply.error_id}", error_id=reply.error_id
            )

    async def wait_motion_done(self, result_id: int | None, timeout_s: float) -> FeedbackState:
        """Wait until the queue command ``result_id`` finished and the arm is idle; ``timeout_s`` is
        controller time (the packets' TimeStamp).

        Raises ControllerError when the controller alarms (with its alarm IDs),
        EmergencyStopError on e-stop, ExecutionError if the arm is disabled, and
        TrajectoryExecutionError when the deadline passes on the controller's clock, and
        RobotCommunicationError when that clock stalls (see :meth:`wait_controller`).
        """
        if result_id is not None and result_id <= self._cut_upto_id:
            raise RobotCommunicationError(
                f"motion {result_id} was cut by a robot link loss (the controller was sent Stop)"
            )
        epoch = self.link_epoch
        fb = self._feedback if self._feedback is not None else await self.next_feedback()
        deadline_ms = fb.timestamp_ms + timeout_s * 1000.0
        seen_running = False
        try:
            async with asyncio.timeout(_wall_guard_s(timeout_s)):
                while True:
                    fb = await self.next_feedback(self.feedback_timeout_s)
                    self._check_epoch(epoch, f"motion {result_id}")
                    if fb.estop:
                        raise EmergencyStopError("emergency stop is active; motion aborted")
                    if fb.in_error:
                        ids, text = await self.describe_alarms()
                        raise (ContactAlarmError if fb.collision else ControllerError)(
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
