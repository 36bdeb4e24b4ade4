"""Grippers behind one small interface; the parallel-jaw gripper on controller DOs."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

from services.common.errors import GripperError, RobotCommunicationError
from services.common.settings import GripperSettings
from services.robot.link import ControllerLink


@dataclass(frozen=True)
class GripperState:
    closed: bool
    object_detected: bool | None  # None when no DI is mapped
    unchanged: bool = False  # the jaws were already as asked: nothing sent (an open of open jaws)


class Gripper(Protocol):
    async def close(self) -> GripperState: ...

    async def open(self, release: bool = False) -> GripperState:
        """``release``: answer once the jaws have let go of what they held, not once fully open."""

    def state(self) -> GripperState: ...


# With an object input mapped, a close that holds nothing is known once the jaws have had this many
# times their actuation time (controller time) without the input: the twin's fingers take 0.32–0.43 s
# of controller time for the configured 0.4 s, so the plain actuation time would cut a real grasp short.
EMPTY_CLOSE_FACTOR = 2.0


class DigitalOutputGripper:
    """Close = ``close_do`` ON (+ ``open_do`` OFF); open = the reverse. The DOs are queued
    commands, so they take effect after motion already queued, like the controller's own
    program would. Every wait is on the controller's clock (the feedback TimeStamp), counted from
    the packet that reports the DO command done: a close ends on the object DI when one is mapped
    (or after ``EMPTY_CLOSE_FACTOR`` × ``actuation_time_s`` without it: closed on nothing), else after
    ``actuation_time_s``; an open after ``actuation_time_s``, or, letting go of a held object, after
    ``release_time_s`` (the jaws clear of it; they go on opening). An open of jaws this gripper has
    already opened sends nothing and waits only for the rest of their stroke."""

    def __init__(self, client: ControllerLink, settings: GripperSettings, command_timeout_s: float = 10.0):
        self._client = client
        self._s = settings
        self._closed = False
        self._known_open = False  # opened by this object and not commanded since
        self._opening_since_ms: float | None = None  # controller stamp the last open took effect at
        self._timeout = command_timeout_s
        self.opens_skipped = 0

    def state(self) -> GripperState:
        return GripperState(self._closed, self._object_detected())

    def _object_detected(self) -> bool | None:
        fb = self._client.feedback
        if self._s.object_di is None or fb is None:
            return None
        return bool((fb.digital_inputs >> (self._s.object_di - 1)) & 1)

    async def _set(self, close: bool, release: bool = False) -> GripperState:
        s = self._s
        if not close and self._known_open:
            self.opens_skipped += 1
            await self._stroke_done()
            return replace(self.state(), unchanged=True)
        self._known_open = False
        self._opening_since_ms = None
        try:
            ids = []
            if s.open_do is not None and close:
                ids.append(await self._client.digital_output(s.open_do, False, s.tool_outputs))
            ids.append(await self._client.digital_output(s.close_do, close, s.tool_outputs))
            if s.open_do is not None and not close:
                ids.append(await self._client.digital_output(s.open_do, True, s.tool_outputs))
            done = await self._client.wait_motion_done(ids[-1], self._timeout)
            self._closed = close
            if close and s.object_di is not None:
                object_bit = s.object_di - 1
                try:
                    await self._client.wait_controller(
                        lambda fb: bool((fb.digital_inputs >> object_bit) & 1),
                        EMPTY_CLOSE_FACTOR * s.actuation_time_s,
                        since_ms=done.timestamp_ms,
                    )
                except TimeoutError:
                    pass  # no object in the jaws: reported through object_detected, decided by the caller
            else:  # jaw travel: nothing to observe but the controller's clock
                if not close:
                    self._opening_since_ms = done.timestamp_ms
                travel = s.release_wait_s if release else s.actuation_time_s
                if travel > 0:
                    await self._client.wait_controller_time(travel, since_ms=done.timestamp_ms)
        except RobotCommunicationError as exc:
            raise GripperError(f"gripper {'close' if close else 'open'} failed: {exc}") from exc
        self._known_open = not close
        return self.state()

    async def close(self) -> GripperState:
        return await self._set(True)

    async def open(self, release: bool = False) -> GripperState:
        return await self._set(False, release)

    async def _stroke_done(self) -> None:
        """Wait out what is left of the last open's stroke (an open that answered on release), on the
        controller's clock; at most one actuation time, whatever the clock did meanwhile (a reconnect)."""
        since, fb = self._opening_since_ms, self._client.feedback
        if since is None or fb is None:
            return
        left_s = min(self._s.actuation_time_s, (since - fb.timestamp_ms) / 1000.0 + self._s.actuation_time_s)
        if left_s > 0:
            try:
                await self._client.wait_controller_time(left_s)
            except RobotCommunicationError as exc:
                raise GripperError(f"gripper open failed: {exc}") from exc
        self._opening_since_ms = None
