"""The e-stop's own dashboard connection: it never waits behind other work.

The main dashboard connection of :class:`services.robot.client.DobotClient` carries every request in
order; a reply held up behind a slow command (or a write buffer full of ServoJ targets) would hold the
e-stop too. This lane is a second connection to the same dashboard port, opened when the client
connects and kept, which carries only EmergencyStop: one request at a time, its own reply parser and
timeout, reopened on demand. Only the e-stop may overtake the main connection's queue: the controller
refuses motion in e-stop, whatever still arrives behind it (a plain Stop must stay in order with the
motion commands before it, so it does not use the lane).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from services import dobot
from services.common.errors import RobotCommunicationError

log = logging.getLogger("pickplace.robot.priority_lane")


class PriorityLane:
    def __init__(self, host: str, port: int, connect_timeout_s: float, request_timeout_s: float):
        self.host = host
        self.port = port
        self.connect_timeout_s = connect_timeout_s
        self.request_timeout_s = request_timeout_s
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._lock = asyncio.Lock()
        self.requests = 0

    @property
    def connected(self) -> bool:
        return self._writer is not None and not self._writer.is_closing()

    async def open(self) -> None:
        """Connect now (best effort: the lane reconnects on its next request if this fails)."""
        async with self._lock:
            with contextlib.suppress(RobotCommunicationError):
                await self._ensure()

    async def _ensure(self) -> None:
        if self.connected:
            return
        try:
            async with asyncio.timeout(self.connect_timeout_s):
                self._reader, self._writer = await asyncio.open_connection(self.host, self.port)
        except (OSError, TimeoutError) as exc:
            self._drop()
            raise RobotCommunicationError(
                f"e-stop lane cannot reach {self.host}:{self.port}: {exc!r}"
            ) from exc

    def _drop(self) -> None:
        if self._writer is not None:
            with contextlib.suppress(Exception):
                self._writer.close()
        self._reader = self._writer = None

    async def close(self) -> None:
        self._drop()

    async def request(self, command: str) -> dobot.Reply:
        """Send ``command`` and return the reply that echoes it; RobotCommunicationError otherwise."""
        async with self._lock:
            await self._ensure()
            assert self._reader is not None and self._writer is not None
            self.requests += 1
            parser = dobot.ReplyParser()
            key = command.replace(" ", "").lower()
            try:
                self._writer.write(command.encode())
                async with asyncio.timeout(self.request_timeout_s):
                    await self._writer.drain()
                    while True:
                        data = await self._reader.read(4096)
                        if not data:
                            raise ConnectionError("connection closed by the controller")
                        for item in parser.feed(data):
                            if isinstance(item, dobot.Reply) and item.echo.replace(" ", "").lower() == key:
                                return item
                            log.warning("e-stop lane: unexpected reply %r", item)
            except (OSError, ConnectionError, TimeoutError) as exc:
                self._drop()  # a lane in an unknown state is not reused
                raise RobotCommunicationError(f"e-stop lane: {command!r} got no reply: {exc!r}") from exc
