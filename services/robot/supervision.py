"""The driver's supervision of every motion (a mixin of :class:`services.robot.driver.RobotDriver`):
the execution monitor and the ServoJ watchdog fed by every feedback packet, the Stop when either trips
(or when a motion's caller is cancelled), the watch of a continuation's gap, and the goal check.

The monitors themselves are pure (:mod:`services.robot.monitor`); this is where their verdicts reach
the arm.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable
from typing import TypeVar

import numpy as np

from services.common.errors import ExecutionError, PathDeviationError
from services.common.settings import Settings
from services.robot.feedback import FeedbackState
from services.robot.link import ControllerLink
from services.robot.monitor import ClockRate, MoveMonitor, StreamMonitor, goal_deviation

log = logging.getLogger("pickplace.robot.driver")

T = TypeVar("T")


class Supervision:
    client: ControllerLink
    settings: Settings
    clock_rate: ClockRate
    _monitor: StreamMonitor | MoveMonitor | None
    _tripped: asyncio.Event
    _gap_task: asyncio.Task[None] | None
    _continue_from: np.ndarray | None
    _continue_tail: np.ndarray | None
    watchdog_trips: int
    monitor_trips: int
    last_fault: ExecutionError | None
    last_fault_stamp_ms: int | None

    @property
    def feedback(self) -> FeedbackState:
        raise NotImplementedError

    # ------------------------------------------------------------------ monitoring
    def _on_feedback(self, fb: FeedbackState) -> None:
        self.clock_rate.on_feedback(fb.timestamp_ms, fb.received_ns)
        monitor = self._monitor
        if monitor is not None and monitor.fault is None and monitor.on_feedback(fb) is not None:
            self.last_fault = monitor.fault
            self.last_fault_stamp_ms = fb.timestamp_ms
            self._tripped.set()

    def _watch(self, monitor: StreamMonitor | MoveMonitor) -> None:
        self._tripped.clear()
        self._monitor = monitor

    async def _monitored(self, work: Awaitable[T], what: str) -> T:
        """Run ``work`` while the monitor watches; when it trips, cut ``work``, stop the arm, raise."""
        task: asyncio.Task[T] = asyncio.ensure_future(work)
        trip = asyncio.ensure_future(self._tripped.wait())
        try:
            await asyncio.wait({task, trip}, return_when=asyncio.FIRST_COMPLETED)
            if task.done():
                return task.result()
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
            raise await self._stop_for_fault(what)
        finally:
            trip.cancel()
            if not task.done():
                task.cancel()

    async def _stop_for_fault(self, what: str) -> ExecutionError:
        """The monitor tripped: stop the arm, count it, and return the error to raise."""
        fault = self.last_fault or ExecutionError(f"{what}: execution monitor tripped")
        self._continue_from = self._continue_tail = None
        self._monitor = None
        log.error("%s: %s", what, fault)
        await self._send_stop(what)
        if "watchdog" in str(fault):
            self.watchdog_trips += 1
        else:
            self.monitor_trips += 1
        return fault

    async def _send_stop(self, why: str) -> None:
        """Stop the controller's queue, even while the caller is being cancelled."""
        stop = asyncio.ensure_future(self.client.stop())
        stop.add_done_callback(_retrieve)  # finished after a cancelled caller: its outcome is logged
        try:
            await asyncio.shield(stop)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # the arm's own alarm or a lost link: the link owes the Stop then
            log.warning("Stop after %s not confirmed: %s", why, exc)

    async def _end_gap_watch(self, handle_trip: bool = True) -> None:
        """A continuation's successor has come (or the driver closes): end the gap's watch; if it
        tripped meanwhile, the arm has been (or now is) stopped and nothing continues."""
        task, self._gap_task = self._gap_task, None
        if task is None:
            return
        if not task.done() and (not handle_trip or not self._tripped.is_set()):
            task.cancel()  # not tripped: nothing to do (a tripped watch is let finish its Stop)
        await asyncio.wait({task})

    async def _watch_gap(self) -> None:
        """After a continuing trajectory: if the next one does not come before the controller runs dry
        (plus the watchdog margin), stop the arm; the next trajectory is then judged from rest."""
        await self._tripped.wait()
        await self._stop_for_fault("the gap after a continuing trajectory")

    async def _check_goal(self, goal: np.ndarray, what: str) -> FeedbackState:
        """The goal check: the measured joints within the goal tolerance of ``goal`` within
        ``goal_settle_s`` of controller time; else the arm is stopped and PathDeviationError raised
        (held off the path's end, as by fingers pressing on the object's edge at a grasp)."""
        r = self.settings.robot
        tol = r.goal_tolerance_rad
        try:
            return await self.client.wait_controller(
                lambda f: abs(goal_deviation(f.q, goal).rad) <= tol, r.goal_settle_s
            )
        except TimeoutError:
            fb = self.feedback
            dev = goal_deviation(fb.q, goal)
            self.monitor_trips += 1
            self.last_fault = PathDeviationError(
                f"execution monitor: {what} ended with {dev.describe()} its goal after "
                f"{r.goal_settle_s:.2f} s (goal tolerance {np.rad2deg(tol):.2f}°); arm stopped"
            )
            self.last_fault_stamp_ms = fb.timestamp_ms
            log.error("%s", self.last_fault)
            await self._send_stop(what)
            raise self.last_fault from None


def _retrieve(task: asyncio.Future[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.warning("Stop not confirmed: %s", task.exception())
