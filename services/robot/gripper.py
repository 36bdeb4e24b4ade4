"""Grippers behind one small interface; the parallel-jaw gripper on controller DOs."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Protocol

from services.common.errors import GripperError, RobotCommunicationError
from services.common.settings import GripperSettings
from services.robot.client import DobotClient


@dataclass(frozen=True)
class GripperState:
    closed: bool
    object_detected: bool | None  # None when no DI is mapped


class Gripper(Protocol):
    async def close(self) -> GripperState: ...

    async def open(self) -> GripperState: ...

    def state(self) -> GripperState: ...


class DigitalOutputGripper:
    """Close = ``close_do`` ON (+ ``open_do`` OFF); open = the reverse. The DOs are queued
    commands, so they take effect after motion already queued, like the controller's own
    program would; then the jaws get ``actuation_time_s`` to move (a physical delay the
    controller cannot report), or, when a DI is mapped, the wait ends on that input."""

    def __init__(self, client: DobotClient, settings: GripperSettings, command_timeout_s: float = 10.0):
        self._client = client
        self._s = settings
        self._closed = False
        self._timeout = command_timeout_s

    def state(self) -> GripperState:
        return GripperState(self._closed, self._object_detected())

    def _object_detected(self) -> bool | None:
        fb = self._client.feedback
        if self._s.object_di is None or fb is None:
            return None
        return bool((fb.digital_inputs >> (self._s.object_di - 1)) & 1)

    async def _set(self, close: bool) -> GripperState:
        s = self._s
        try:
            ids = []
            if s.open_do is not None and close:
                ids.append(await self._client.digital_output(s.open_do, False, s.tool_outputs))
            ids.append(await self._client.digital_output(s.close_do, close, s.tool_outputs))
            if s.open_do is not None and not close:
                ids.append(await self._client.digital_output(s.open_do, True, s.tool_outputs))
            last = ids[-1]
            await self._client.wait_motion_done(last, self._timeout)
        except RobotCommunicationError as exc:
            raise GripperError(f"gripper {'close' if close else 'open'} failed: {exc}") from exc
        self._closed = close
        if close and s.object_di is not None:
            object_bit = s.object_di - 1
            try:
                await self._client.wait_feedback(
                    lambda fb: bool((fb.digital_inputs >> object_bit) & 1),
                    max(s.actuation_time_s, 0.05),
                )
            except TimeoutError:
                pass  # no object in the jaws: reported through object_detected, decided by the caller
        elif s.actuation_time_s > 0:
            await asyncio.sleep(s.actuation_time_s)  # jaw travel time: nothing to observe
        return self.state()

    async def close(self) -> GripperState:
        return await self._set(True)

    async def open(self) -> GripperState:
        return await self._set(False)
