"""The robot driver core: safety-checked operations on one Dobot controller.

One implementation for the real Nova5 and the simulated one (the robot is
simulated at the wire). Every command is checked by :class:`SafetyLimits`
before it leaves; failed motion steps follow seed 001's policy (clear the
error, re-enable, wait, retry up to N times, then raise); stop and e-stop
bypass everything else and abort trajectory streaming at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, replace
from math import ceil
from typing import TypeVar

import numpy as np

from services.common.errors import (
    ContactAlarmError,
    ContinuationLateError,
    ControllerError,
    EmergencyStopError,
    ExecutionError,
    InvalidInputError,
    LimitViolationError,
    RobotBusyError,
    RobotCommunicationError,
    StartMismatchError,
    TrajectoryExecutionError,
)
from services.common.settings import Settings
from services.dobot import RobotMode
from services.kinematics.robot_models import RobotSpec
from services.kinematics.trajectory import JointTrajectory
from services.robot.feedback import FeedbackState, LinkState
from services.robot.gripper import DigitalOutputGripper, GripperState
from services.robot.link import ControllerLink, PipelinedServo
from services.robot.monitor import ClockRate, MoveMonitor, StreamMonitor
from services.robot.resume import ease_in_offset, retime_from_rest
from services.robot.safety import SafetyLimits
from services.robot.supervision import Supervision

log = logging.getLogger("pickplace.robot.driver")

T = TypeVar("T")

START_TOLERANCE_RAD = np.deg2rad(1.0)  # a trajectory must start this close to the measured joints
# targets in hand at the end of a trajectory that continues (0.36 s at 30 ms): the controller keeps
# moving while the next trajectory's request travels (a starved ServoJ queue stops the arm dead). The
# call returns once its last target is in hand, that far ahead of the arm: what must wait for the arm
# to get there (the grasp check after LIFT) waits for the joint states to show it
CONTINUE_TARGETS = 12
# a target is sent on feedback no older than this (host clock): after the host stalled, the packets
# that queued meanwhile are read first (the controller may have run dry in the meantime)
STALE_FEEDBACK_NS = 20_000_000
# a target that would be a step from rest is sent only while the controller holds targets for at least
# this long (host time): the packet behind the decision and the target itself may each be late by a
# few scheduler slices on a loaded host; less than that in hand, the stream is resumed from rest instead
RESUME_MARGIN_S = 0.05
# ... or twice the longest a recent batch took from the packet behind its decision to its replies
# (controller time): a loaded host (or a simulator slowed with it) learns its own latency
SEND_LAGS_KEPT = 64
LAG_FACTOR = 2.0
MAX_WINDOW = 16  # the most targets held ahead at 1x, however slow the host (0.48 s at 30 ms) ...
# ... and at N x as many: the host's stalls are in its own time, so a simulator at 2x holds 0.96 s of its
# clock (0.48 s of the host's) and its learned margin (twice a stall, in controller time) still fits


def stream_window(base: int, rate: float, margin_ms: float, period_s: float) -> int:
    """How many ServoJ targets to keep in hand: ``base`` (scaled by the controller's clock ``rate``), or
    enough to hold twice the send ``margin_ms`` (controller time), at most ``MAX_WINDOW`` of host time.
    A margin the window could not hold would turn every at-speed stream into a stop and a resume."""
    cap = round(MAX_WINDOW * max(1.0, rate))
    return min(cap, max(base, round(base * rate), ceil(2 * margin_ms / (1000 * period_s))))


@dataclass(frozen=True)
class MoveResult:
    final_q: np.ndarray
    duration_s: float
    attempts: int
    stopped_early: bool = False  # a guarded move's stop condition fired
    resumed: int = 0  # times the stream ran dry (the host fell behind) and was resumed from rest


StopCondition = Callable[[FeedbackState], bool]


class RobotDriver(Supervision):
    def __init__(
        self,
        client: ControllerLink,
        spec: RobotSpec,
        settings: Settings,
        T_flange_tool: np.ndarray | None = None,
    ):
        self.client = client
        self.spec = spec
        self.settings = settings
        self.limits = SafetyLimits(
            spec, settings.robot.workspace, settings.robot.max_velocity_scale, T_flange_tool
        )
        self.gripper = DigitalOutputGripper(client, settings.gripper)
        self._abort = asyncio.Event()
        self._abort_by_estop = False  # what set ``_abort``: the e-stop, or a plain stop
        self._motion_lock = asyncio.Lock()
        # the last target of a trajectory that continues (streamed, not yet executed): the next
        # trajectory starts from it, not from the measured joints, which trail it while moving
        self._continue_from: np.ndarray | None = None
        self._continue_id: int | None = None  # the queue ID of that target
        self._continue_tail: np.ndarray | None = None  # its last two targets (the acceleration check)
        # execution monitoring: the monitor of the motion under way (a stream, a continuation's gap, a
        # move), fed every packet by one listener; a trip sets ``_tripped`` (the running motion stops)
        self._monitor: StreamMonitor | MoveMonitor | None = None
        self._tripped = asyncio.Event()
        self._gap_task: asyncio.Task[None] | None = None  # watches a continuation until the next comes
        self.watchdog_trips = 0  # ServoJ streams stopped for want of targets
        self.monitor_trips = 0  # motions stopped for leaving their path or missing their goal
        self.stream_resumes = 0  # ServoJ streams that fell behind and were resumed from rest
        # controller ms from the packet behind a ServoJ batch's decision to its replies (recent batches)
        self._send_lags_ms: deque[float] = deque(maxlen=SEND_LAGS_KEPT)
        self.last_fault: ExecutionError | None = None
        self.last_fault_stamp_ms: int | None = None  # the packet that tripped it (controller clock)
        # the look-ahead covers the host's latency, which is wall time: a controller clock that runs N×
        # faster (a simulator) needs N× the targets in hand
        self.clock_rate = ClockRate()

    async def start(self) -> None:
        self.client.add_listener(self._on_feedback)
        await self.client.connect()
        await self._send_ratios()

    async def close(self) -> None:
        """Stop watching (the link is closed by its owner)."""
        self.client.remove_listener(self._on_feedback)
        await self._end_gap_watch(handle_trip=False)
        self._monitor = None

    async def _send_ratios(self) -> None:
        await self.client.speed_factor(self.settings.robot.speed_ratio)
        await self.client.acceleration_ratio(self.settings.robot.acc_ratio)

    async def update_settings(self, new: Settings, changed: list[str]) -> None:
        """A live configuration change (PUT /config): the workspace box guards the next command; speed
        and acceleration ratios go to the controller at once (immediate commands, also mid-motion)."""
        self.settings = new
        if any(c.startswith("robot.workspace") for c in changed):
            self.limits = replace(self.limits, workspace=new.robot.workspace)
        if {"robot.speed_ratio", "robot.acc_ratio"} & set(changed):
            await self._send_ratios()

    # ------------------------------------------------------------------ state
    @property
    def feedback(self) -> FeedbackState:
        fb = self.client.feedback
        if fb is None:
            raise RobotCommunicationError("no feedback received from the controller yet")
        return fb

    def joint_positions(self) -> np.ndarray:
        return self.feedback.q.copy()

    # ------------------------------------------------------------------ power
    async def enable(self) -> None:
        fb = self.client.feedback
        if fb is not None and fb.in_error:
            await self.client.clear_error()
        await self.client.enable()
        await self.client.wait_feedback(
            lambda f: f.robot_mode in (RobotMode.ENABLE, RobotMode.RUNNING),
            self.settings.robot.request_timeout_s,
        )

    async def disable(self) -> None:
        self._abort.set()
        await self.client.disable()

    async def clear_error(self) -> None:
        self._continue_from = None
        await self.client.clear_error()

    async def recover(self) -> None:
        """Seed 001's recovery step: clear the error, re-enable, wait."""
        self._continue_from = None
        await self.client.clear_error()
        await self.client.enable()
        if self.settings.robot.retry_wait_s > 0:
            await asyncio.sleep(self.settings.robot.retry_wait_s)

    # ------------------------------------------------------------------ stop
    async def stop(self) -> None:
        """Stop queued motion and abort any trajectory being streamed."""
        self._abort_by_estop = False
        self._abort.set()
        self._forget_stream()
        await self.client.stop()

    async def emergency_stop(self, release: bool = False) -> None:
        """Press (or release) the software e-stop. Sent before anything else is looked at."""
        if not release:
            # a stream cut by the e-stop fails as an EmergencyStopError (the task's wait-for-operator
            # path), even before the feedback shows the e-stop
            self._abort_by_estop = True
            self._abort.set()
            self._forget_stream()
        await self.client.emergency_stop(press=not release)

    def _forget_stream(self) -> None:
        """Nothing continues: no next trajectory follows the last one, no monitor watches a gap."""
        self._continue_from = self._continue_tail = None
        if self._gap_task is not None and not self._gap_task.done():
            self._gap_task.cancel()
        self._gap_task = None
        if isinstance(self._monitor, StreamMonitor) and not self._motion_lock.locked():
            self._monitor = None

    # ------------------------------------------------------------------ motion
    async def _with_retries(self, what: str, step: Callable[[], Awaitable[T]]) -> tuple[T, int]:
        retries = self.settings.robot.step_retries
        last: Exception | None = None
        for attempt in range(retries + 1):
            try:
                return await step(), attempt + 1
            except ControllerError as exc:
                last = exc
                if self._abort.is_set():
                    if self._abort_by_estop:  # the e-stop's alarm: the operator's path, not a retry
                        raise EmergencyStopError(f"emergency stop during {what}: {exc}") from exc
                    break
                log.warning("%s failed (attempt %d/%d): %s", what, attempt + 1, retries + 1, exc)
                if attempt < retries:
                    await self.recover()
        raise TrajectoryExecutionError(f"{what} failed after {retries + 1} attempts: {last}") from last

    async def move_joints(
        self,
        q_goal: np.ndarray,
        speed_ratio: int | None = None,
        linear: bool = False,
        acceleration_ratio: int | None = None,
    ) -> MoveResult:
        q_goal = self.limits.check_all(np.asarray(q_goal, dtype=float))
        v = None if speed_ratio is None else int(speed_ratio)
        if v is not None and not 1 <= v <= 100:
            raise InvalidInputError(f"speed_ratio must be 1-100, got {v}")
        a = None if acceleration_ratio is None else int(acceleration_ratio)
        if a is not None and not 1 <= a <= 100:
            raise InvalidInputError(f"acceleration ratio must be 1-100, got {a}")
        self._refuse_if_busy("MoveJoints")
        async with self._motion_lock:
            await self._end_gap_watch()
            self._forget_stream()
            self._abort.clear()
            self._abort_by_estop = False
            t0 = time.perf_counter()

            async def step() -> FeedbackState:
                if linear:
                    rid = await self.client.mov_l(q_goal, a=a, v=v)
                else:
                    rid = await self.client.mov_j(q_goal, a=a, v=v)
                return await self.client.wait_motion_done(rid, self.settings.robot.motion_timeout_s)

            self._watch(MoveMonitor(self.settings.robot.path_tolerance_rad))
            try:
                fb, attempts = await self._monitored(self._with_retries("MoveJoints", step), "MoveJoints")
                fb = await self._check_goal(q_goal, "MoveJoints")
            except asyncio.CancelledError:  # the caller is gone (a dead client): the arm stops
                await self._send_stop("a cancelled MoveJoints")
                raise
            finally:
                self._monitor = None
            return MoveResult(fb.q.copy(), time.perf_counter() - t0, attempts)

    def _servo_targets(self, traj: JointTrajectory, period: float) -> np.ndarray:
        # the tolerance: a duration that is a multiple of the period (a blended segment's) gets no
        # extra, repeated last target, which the controller would hold for a whole period
        n = max(1, int(np.ceil(traj.duration / period - 1e-6)))
        ts = np.minimum(np.arange(1, n + 1) * period, traj.duration)
        q = traj.sample(ts, derivatives=0)[0]
        return np.atleast_2d(q)

    async def execute_trajectory(
        self,
        traj: JointTrajectory,
        servo_period_s: float | None = None,
        stop_when: StopCondition | None = None,
        continues: bool = False,
    ) -> MoveResult:
        """Stream the trajectory as ServoJ targets, one per period, in real time.

        ``continues``: another trajectory follows without a stop (this one ends in motion): return as
        soon as the last target is queued; the next call starts from that target, checked against it.

        Checked first, as a whole and under the motion lock (a second request while one streams is
        refused as busy): the link, joint names, the start against the measured joints (or the last
        queued target), every streamed target against joint and workspace limits, and the joint speeds
        and accelerations between targets. Streaming stops at once on stop/e-stop or
        when the controller alarms. A guarded move passes ``stop_when``: as a
        feedback packet satisfies it the queue is stopped and the result says so.
        """
        if tuple(traj.joint_names) != tuple(self.spec.joint_names):
            raise InvalidInputError(
                f"trajectory joints {list(traj.joint_names)} do not match the robot's {list(self.spec.joint_names)}"
            )
        if continues and stop_when is not None:
            raise InvalidInputError("a guarded move ends at rest: it cannot continue into the next one")
        period = servo_period_s or self.settings.robot.servo_period_s
        if not 0.004 <= period <= 1.0:
            raise InvalidInputError(f"servo period must be within 4 ms..1 s, got {period}")
        self._refuse_if_busy("trajectory")
        async with self._motion_lock:
            await self._end_gap_watch()  # a continuation's successor: the gap's watch ends here
            # every check runs under the lock, on the state the stream will start from: a request that
            # came in while another motion ran is judged against where that motion left the arm
            try:
                targets, q_before, following = self._checked_targets(traj, period)
            except ContinuationLateError:
                await self._come_to_rest()  # the caller plans again from where the arm then stands
                raise
            self._abort.clear()
            self._abort_by_estop = False
            r = self.settings.robot
            monitor = self._monitor if following and isinstance(self._monitor, StreamMonitor) else None
            if monitor is None:
                monitor = StreamMonitor(q_before[-1], period, r.path_tolerance_rad, r.servo_watchdog_margin_s)
            monitor.period_s = period
            monitor.owed = True
            monitor.ends_slowed = False
            self._watch(monitor)
            keep_watching = False
            try:
                if stop_when is not None:
                    return await self._guarded(targets, period, stop_when, monitor)
                res = await self._monitored(
                    self._stream(targets, period, monitor, wait_done=not continues), "trajectory"
                )
                if not continues or monitor.ends_slowed:  # (resumed from rest, it ends at rest)
                    fb = await self._check_goal(targets[-1], "trajectory")
                    return replace(res, final_q=fb.q.copy())
                keep_watching = True
            except asyncio.CancelledError:  # the caller is gone (a dead client): the arm stops now
                self._continue_from = self._continue_tail = None
                await self._send_stop("a cancelled trajectory")
                raise
            finally:
                if not keep_watching:
                    self._monitor = None
            # the next trajectory continues from here; until it comes, the gap is watched
            self._continue_from = targets[-1].copy()
            self._continue_tail = monitor.tail()  # as sent (a stream resumed from rest is re-timed)
            self._gap_task = asyncio.create_task(self._watch_gap(), name="robot-continuation-watch")
            return res

    async def _come_to_rest(self) -> None:
        """Until the feedback shows the arm at rest (on the controller's clock, at most the goal settle
        time): a motion that ran out leaves the arm tracking on behind its last target for a moment."""
        with contextlib.suppress(TimeoutError):
            await self.client.wait_controller(lambda f: f.at_rest, self.settings.robot.goal_settle_s)

    def _refuse_if_busy(self, what: str) -> None:
        if self._motion_lock.locked():
            raise RobotBusyError(
                f"{what} refused: the arm is executing another motion (one stream at a time); "
                "wait for it to end or stop it first"
            )

    def _checked_targets(self, traj: JointTrajectory, period: float) -> tuple[np.ndarray, np.ndarray, bool]:
        """The ServoJ targets of ``traj``, the two positions they continue from, and whether they
        follow a continuing trajectory still under way, after every check:
        link, e-stop, alarm, the start against where the arm is (or its last queued target), joint and
        workspace limits, joint speeds and accelerations. Raises before anything is sent."""
        if self.client.link is not LinkState.UP:
            raise RobotCommunicationError(
                f"robot link is {self.client.link.value}: the last feedback may be stale; nothing sent"
            )
        fb = self.feedback
        if fb.estop:
            raise EmergencyStopError("emergency stop is active")
        if fb.in_error:
            raise ControllerError("controller is in alarm; clear it before executing a trajectory")
        continuing = self._continue_from is not None  # the last trajectory flowed on into this one
        following = continuing and self._still_queued(fb)
        # following: the previous trajectory's targets are still queued or running; start from its last
        if following and self._continue_from is not None and self._continue_tail is not None:
            q_now, q_before = self._continue_from, self._continue_tail
        else:
            q_now = fb.q.copy()
            q_before = np.vstack([q_now, q_now])  # at rest
        self._continue_from = self._continue_tail = None
        start_err = float(np.max(np.abs(traj.positions[0] - q_now)))
        if not np.isfinite(start_err) or start_err > START_TOLERANCE_RAD:
            if continuing and not following and np.isfinite(start_err) and traj.starts_in_motion:
                # the motion it continues ran out before it came (a busy machine): the arm comes to rest
                # at that motion's end, lagging behind it as it tracks (seed 1074: 1.59° under load)
                raise ContinuationLateError(
                    f"trajectory starts {np.rad2deg(start_err):.2f}° away from the measured joints: the "
                    "motion it continues has already run out and the arm comes to rest behind it; plan "
                    "it again from rest"
                )
            raise StartMismatchError(
                f"trajectory starts {np.rad2deg(start_err):.2f}° away from the "
                f"{'last queued target' if following else 'measured joints'} "
                f"(tolerance {np.rad2deg(START_TOLERANCE_RAD):.1f}°); plan from the current state"
            )
        targets = self._servo_targets(traj, period)
        self.limits.check_all(targets, "trajectory")
        self.limits.check_velocities(targets, period, q_start=q_now)
        try:
            self.limits.check_accelerations(targets, period, q_before)
        except LimitViolationError as exc:
            if following:
                raise
            if traj.starts_in_motion:
                raise ContinuationLateError(
                    f"{exc}: it continues a motion that has already ended (the arm is at rest); "
                    "plan it again from rest"
                ) from exc
            targets = self._eased_in(q_now, targets, traj, period, exc)
        return targets, q_before, following

    def _eased_in(
        self, q_now: np.ndarray, targets: np.ndarray, traj: JointTrajectory, period: float, exc: Exception
    ) -> np.ndarray:
        """A plan from rest that starts a hair off the measured joints, eased in from where the arm is.

        A time-optimal plan starts at full acceleration, so an arm that settled a few thousandths of a
        degree from the plan's start (well within the start tolerance) turns the first targets into a
        step beyond the acceleration limit. When the plan passes from its own start, the offset is faded
        out over its first targets (:func:`ease_in_offset`, every target checked again); a plan beyond
        the limits from its own start is refused as it is (``exc``). A plan to rest too short to fade the
        offset out within the limits (seed 1108 of the eval: a 0.13 s straightening turn of the held rod,
        five targets, a little off where the arm rested) goes through the same targets re-timed from
        rest where the arm is (:func:`retime_from_rest`, the ramp of a resumed stream), slower but on
        its path."""
        start = np.asarray(traj.positions[0], dtype=float)
        off_deg = float(np.rad2deg(np.max(np.abs(q_now - start))))
        try:
            self.limits.check_accelerations(targets, period, np.vstack([start, start]))
        except LimitViolationError:
            raise exc from None
        try:
            eased = ease_in_offset(q_now, start, targets, period, self.limits)
        except LimitViolationError:
            if traj.ends_in_motion:  # what continues it expects the plan's own end
                raise exc from None
            try:
                res = retime_from_rest(q_now, targets, period, self.limits)
            except LimitViolationError:
                raise exc from None
            log.info("trajectory re-timed from rest: it starts %.4f° off the measured joints", off_deg)
            return res.targets
        log.info("trajectory eased in: it starts %.4f° off the measured joints", off_deg)
        return eased

    async def _stream(
        self, targets: np.ndarray, period: float, monitor: StreamMonitor, wait_done: bool = True
    ) -> MoveResult:
        """Send ServoJ targets, keeping at most ``servo_lookahead`` queued ahead of the one the
        controller is executing (flow control by CurrentCommandId from the feedback stream).
        Pacing therefore follows the controller's own clock — real time on hardware, any speed
        in the simulator — and the controller never starves nor builds a long queue.

        A target that would be a step in speed were the controller to have run dry when it arrives is
        sent only while the controller cannot run dry for another margin (:meth:`_send_margin_ms`: a
        fixed one, or what recent sends took) by the schedule of what it holds
        (:meth:`StreamMonitor.dry_at_ms`); the window of targets in hand grows to keep that margin. Otherwise (the host fell
        behind) nothing is sent until the controller rests at the last target, and the rest of the
        stream is re-timed from rest (:func:`services.robot.resume.retime_from_rest`): no target ever
        reaches a controller that has stopped as a step from rest."""
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        base = self.settings.robot.servo_lookahead
        if not wait_done:  # the next trajectory's request comes in while these run: more in hand
            base = max(base, CONTINUE_TARGETS)
        ids: list[int | None] = []
        resumed = 0
        via_rest = False  # the host fell behind: let the controller run dry, then resume from rest
        k = 0
        while k < len(targets):
            while True:
                fb = self.feedback
                if self._abort.is_set() and not (fb.estop or self._abort_by_estop):
                    raise ExecutionError(f"trajectory aborted by stop at step {k}/{len(targets)}")
                if fb.estop or self._abort.is_set():
                    raise EmergencyStopError(f"emergency stop during trajectory step {k}")
                if fb.in_error:
                    alarm_ids, text = await self.client.describe_alarms()
                    raise (ContactAlarmError if fb.collision else ControllerError)(
                        f"controller alarm during trajectory step {k}: {text}", alarms=tuple(alarm_ids)
                    )
                if time.time_ns() - fb.received_ns > STALE_FEEDBACK_NS:
                    # after a stall: decide on the arm's state now (the packets that queued meanwhile
                    # are read first; the controller may have run dry since the packet in hand)
                    await self.client.next_feedback()
                    continue
                if monitor.fault is not None:  # tripped: the monitored run cuts this task, stops the arm
                    await asyncio.Event().wait()
                held = monitor.unstarted(fb.current_command_id)
                # the margin the host needs, and enough targets in hand to keep it
                margin_ms = self._send_margin_ms()
                window = stream_window(base, self.clock_rate.rate, margin_ms, period)
                if via_rest:
                    if held == 0 and fb.robot_mode != RobotMode.RUNNING:  # at rest at the last target
                        targets = np.vstack([targets[:k], self._resume(monitor, targets[k:], period, k)])
                        resumed += 1
                        via_rest = False
                        monitor.owed = True
                        break
                elif held < window:
                    if monitor.targets_sent == 0 or self._safe_from_rest(monitor, targets[k], period):
                        break  # (a fresh stream's first targets leave in one write: queued together)
                    ahead_ms = monitor.dry_at_ms(fb) - self._controller_now_ms(fb)
                    if ahead_ms >= margin_ms:
                        break
                    via_rest = True
                    # the arm is let come to rest at the last target: not a starved stream, until resumed
                    monitor.owed = False
                    log.warning(
                        "ServoJ stream fell behind at step %d/%d (the controller may run dry %.0f ms from "
                        "now): resuming it from rest",
                        k + 1,
                        len(targets),
                        ahead_ms,
                    )
                    continue
                await self.client.next_feedback()
            # pipelined: the targets that fill the window go out together, none waits for another's reply
            batch = targets[k : k + max(1, window - monitor.unstarted(fb.current_command_id))]
            if log.isEnabledFor(logging.DEBUG):
                log.debug(
                    "ServoJ %d-%d/%d: %d in hand, dry at %.0f ms, controller now ~%.0f ms",
                    k + 1,
                    k + len(batch),
                    len(targets),
                    monitor.unstarted(fb.current_command_id),
                    monitor.dry_at_ms(fb),
                    self._controller_now_ms(fb),
                )
            rids = await self._send_targets(batch, period)
            self._send_lags_ms.append((time.time_ns() - fb.received_ns) / 1e6 * self.clock_rate.rate)
            for q, rid in zip(batch, rids, strict=True):
                ids.append(rid)
                monitor.sent(q, rid, fb.timestamp_ms)
                k += 1
        wait_done = wait_done or monitor.ends_slowed
        monitor.owed = not wait_done  # a stream that ends may run dry; a continuing one must not
        if not wait_done:  # the next trajectory continues the queue: the last target is the result
            self._continue_id = ids[-1]
            return MoveResult(targets[-1].copy(), loop.time() - t0, 1, resumed=resumed)
        fb = await self.client.wait_motion_done(
            ids[-1], max(self.settings.robot.motion_timeout_s, 2 * period)
        )
        return MoveResult(fb.q.copy(), loop.time() - t0, 1, resumed=resumed)

    async def _send_targets(self, batch: np.ndarray, period: float) -> list[int | None]:
        """ServoJ targets in one write where the link can (they reach the controller together)."""
        if isinstance(self.client, PipelinedServo):
            return await self.client.servo_j_many(list(batch), period)
        return [await self.client.servo_j(q, period) for q in batch]

    def _safe_from_rest(self, monitor: StreamMonitor, q: np.ndarray, period: float) -> bool:
        """Whether ``q`` is within the limits even as a step from rest at the stream's last target."""
        last = monitor.tail()[-1]
        try:
            self.limits.check_velocities(q[None], period, q_start=last)
            self.limits.check_accelerations(q[None], period, np.vstack([last, last]))
        except LimitViolationError:
            return False
        return True

    def _send_margin_ms(self) -> float:
        """How long (controller ms) the controller must still hold targets when one that would be a step
        from rest is sent: ``RESUME_MARGIN_S``, or ``LAG_FACTOR`` × the longest recent send."""
        learned = LAG_FACTOR * max(self._send_lags_ms, default=0.0)
        return max(RESUME_MARGIN_S * 1000.0 * self.clock_rate.rate, learned)

    def _controller_now_ms(self, fb: FeedbackState) -> float:
        """The controller clock now, from the packet in hand and the host time since it came."""
        return fb.timestamp_ms + (time.time_ns() - fb.received_ns) / 1e6 * self.clock_rate.rate

    def _resume(self, monitor: StreamMonitor, remaining: np.ndarray, period: float, k: int) -> np.ndarray:
        """The controller rests at the stream's last target: the rest of it, re-timed from rest."""
        try:
            res = retime_from_rest(monitor.tail()[-1], remaining, period, self.limits)
        except LimitViolationError as exc:
            raise ExecutionError(f"the ServoJ stream ran dry at step {k}; {exc}; arm at rest") from exc
        monitor.from_rest()
        monitor.ends_slowed = not res.reaches_plan
        self.stream_resumes += 1
        log.warning(
            "ServoJ stream resumed from rest at step %d: %d targets left re-timed (%.2f s ramp)",
            k + 1,
            len(res.targets),
            res.ramp_s,
        )
        return res.targets

    async def _guarded(
        self, targets: np.ndarray, period: float, stop_when: StopCondition, monitor: StreamMonitor
    ) -> MoveResult:
        """Stream while watching every feedback packet; the first one that satisfies
        ``stop_when`` cancels streaming and stops the controller's queue."""
        loop = asyncio.get_running_loop()
        fired = asyncio.Event()
        t0 = loop.time()

        def watch(fb: FeedbackState) -> None:
            if not fired.is_set() and stop_when(fb):
                fired.set()

        self.client.add_listener(watch)
        stream = asyncio.create_task(
            self._monitored(self._stream(targets, period, monitor), "guarded move"), name="guarded-stream"
        )
        trigger = asyncio.create_task(fired.wait(), name="guarded-trigger")
        try:
            await asyncio.wait({stream, trigger}, return_when=asyncio.FIRST_COMPLETED)
            if stream.done():
                return stream.result()
            stream.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await stream
            await self.client.stop()
            fb = await self.client.wait_feedback(lambda f: f.robot_mode != RobotMode.RUNNING, 2.0)
            return MoveResult(fb.q.copy(), loop.time() - t0, 1, stopped_early=True)
        finally:
            trigger.cancel()
            if not stream.done():
                stream.cancel()
            self.client.remove_listener(watch)

    def _still_queued(self, fb: FeedbackState) -> bool:
        """Whether the arm is still on its way to the last target of a continuing trajectory (not yet
        started, running, or just arrived) — not halted elsewhere by a stop or an alarm."""
        assert self._continue_from is not None
        if self._continue_id is not None and fb.current_command_id < self._continue_id:
            return fb.robot_mode in (RobotMode.RUNNING, RobotMode.ENABLE)
        return float(np.max(np.abs(fb.q - self._continue_from))) <= START_TOLERANCE_RAD

    # ------------------------------------------------------------------ grasp (LLD §13.2)
    async def execute_grasp(
        self,
        T_base_tool: np.ndarray,
        approach_m: float = 0.10,
        lift_m: float = 0.10,
        speed_scale: float = 0.3,
    ) -> GripperState:
        """Open, move above the grasp along the tool axis, descend in a straight line, close, lift
        (:func:`services.robot.grasp_sequence.execute_grasp`)."""
        from services.robot.grasp_sequence import execute_grasp

        return await execute_grasp(self, T_base_tool, approach_m, lift_m, speed_scale)

    # ------------------------------------------------------------------ gripper
    async def set_gripper(self, close: bool, release: bool = False) -> GripperState:
        """``release`` (an open only): answer once the jaws have let go of the held object."""
        if close and release:
            raise InvalidInputError("release applies to an open of the gripper, not to a close")
        return await (self.gripper.close() if close else self.gripper.open(release))
