"""The feedback side of a controller link: the newest state, its listeners, and every wait on the
controller's clock (each state's ``timestamp_ms``), with a wall-clock guard only against a controller
whose clock stands still. URLink is one of these; the loop thread is the only writer."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

from services.common.errors import RobotCommunicationError
from services.robot.feedback import ClientState, FeedbackState, LinkState
from services.robot.link import FeedbackListener

WALL_GUARD_MIN_S = 30.0  # a controller-clock wait also ends after this much wall time (+20x its length)


class FeedbackStream:
    def __init__(self, host: str, feedback_timeout_s: float):
        self.host = host
        self.feedback_timeout_s = feedback_timeout_s
        self.state = ClientState.IDLE
        self.link = LinkState.DOWN
        self.link_epoch = 0  # +1 at every loss
        self._feedback: FeedbackState | None = None
        self._wake = asyncio.Event()
        self._wake_error: RobotCommunicationError | None = None
        self._listeners: list[FeedbackListener] = []

    def _publish(self, fb: FeedbackState) -> None:
        """A new state: stored, waiters woken, listeners called."""
        self._feedback = fb
        wake, self._wake = self._wake, asyncio.Event()
        wake.set()
        for cb in list(self._listeners):
            cb(fb)

    def _fail_waiters(self, error: RobotCommunicationError) -> None:
        self._wake_error = error
        wake, self._wake = self._wake, asyncio.Event()
        wake.set()

    @property
    def feedback(self) -> FeedbackState | None:
        return self._feedback

    def add_listener(self, callback: FeedbackListener) -> None:
        self._listeners.append(callback)

    def remove_listener(self, callback: FeedbackListener) -> None:
        with contextlib.suppress(ValueError):
            self._listeners.remove(callback)

    async def next_feedback(self, timeout_s: float | None = None) -> FeedbackState:
        wake = self._wake
        try:
            async with asyncio.timeout(self.feedback_timeout_s if timeout_s is None else timeout_s):
                await wake.wait()
        except TimeoutError:
            raise RobotCommunicationError(
                f"no RTDE feedback from UR {self.host} (link {self.link.value})"
            ) from None
        if self._wake_error is not None and (self._feedback is None or self.link is not LinkState.UP):
            raise self._wake_error
        assert self._feedback is not None
        return self._feedback

    async def wait_feedback(
        self, predicate: Callable[[FeedbackState], bool], timeout_s: float
    ) -> FeedbackState:
        return await self.wait_controller(predicate, timeout_s)

    async def wait_controller(
        self,
        predicate: Callable[[FeedbackState], bool],
        controller_timeout_s: float,
        *,
        since_ms: int | None = None,
        wall_guard_s: float | None = None,
    ) -> FeedbackState:
        epoch = self.link_epoch
        fb = self._feedback if self._feedback is not None else await self.next_feedback()
        deadline_ms = (fb.timestamp_ms if since_ms is None else since_ms) + controller_timeout_s * 1000.0
        guard = wall_guard_s if wall_guard_s is not None else WALL_GUARD_MIN_S + 20.0 * controller_timeout_s
        try:
            async with asyncio.timeout(guard):
                while not predicate(fb):
                    if fb.timestamp_ms >= deadline_ms:
                        raise TimeoutError(
                            f"feedback condition not met within {controller_timeout_s:.2f}s of controller time"
                        )
                    fb = await self.next_feedback()
                    if self.link_epoch != epoch:
                        raise RobotCommunicationError("robot link lost during a controller-clock wait")
        except TimeoutError as exc:
            if "controller time" in str(exc):
                raise
            raise RobotCommunicationError(
                f"the UR {self.host} clock did not advance {controller_timeout_s:.2f}s within {guard:.0f}s"
            ) from None
        return fb

    async def wait_controller_time(self, duration_s: float, since_ms: int | None = None) -> FeedbackState:
        fb = self._feedback if self._feedback is not None else await self.next_feedback()
        until_ms = (fb.timestamp_ms if since_ms is None else since_ms) + duration_s * 1000.0
        return await self.wait_controller(
            lambda f: f.timestamp_ms >= until_ms, duration_s + 1.0, since_ms=since_ms
        )
