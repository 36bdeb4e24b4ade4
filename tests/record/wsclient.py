"""A minimal client of the Foxglove WebSocket protocol (``foxglove.websocket.v1``; foxglove-sdk ≥ 0.x names
the same protocol ``foxglove.sdk.v1`` in the handshake): serverInfo, advertise, subscribe, binary message data."""

from __future__ import annotations

import asyncio
import json
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import websockets

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
OP_MESSAGE_DATA = 0x01


@dataclass
class FoxgloveClient:
    url: str
    server_info: dict[str, Any] = field(default_factory=dict)
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)  # topic → advertised channel
    received: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)  # topic → (log time, payload)
    _subs: dict[int, str] = field(default_factory=dict)
    _ws: Any = None
    _task: asyncio.Task[None] | None = None
    _advertised: asyncio.Event = field(default_factory=asyncio.Event)
    _message: asyncio.Event = field(default_factory=asyncio.Event)

    async def __aenter__(self) -> FoxgloveClient:
        self._ws = await websockets.connect(self.url, subprotocols=SUBPROTOCOLS, max_size=None)  # type: ignore[list-item]
        self._task = asyncio.create_task(self._receive())
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
        await self._ws.close()

    async def _receive(self) -> None:
        async for frame in self._ws:
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "serverInfo":
                    self.server_info = msg
                elif msg["op"] == "advertise":
                    for ch in msg["channels"]:
                        self.channels[ch["topic"]] = ch
                    self._advertised.set()
            elif frame[0] == OP_MESSAGE_DATA:
                sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                self.received.setdefault(self._subs[sub_id], []).append((log_time, bytes(frame[13:])))
                self._message.set()

    async def wait_for_channels(self, topics: set[str], timeout_s: float = 30.0) -> None:
        async with asyncio.timeout(timeout_s):
            while not topics <= set(self.channels):
                self._advertised.clear()
                await self._advertised.wait()

    async def subscribe(self, *topics: str) -> None:
        subs = []
        for topic in topics:
            sub_id = len(self._subs) + 1
            self._subs[sub_id] = topic
            subs.append({"id": sub_id, "channelId": self.channels[topic]["id"]})
        await self._ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def count(self, topic: str) -> int:
        return len(self.received.get(topic, []))

    async def wait_until(self, done: Callable[[], bool], timeout_s: float = 30.0) -> None:
        """Until ``done()`` holds, checked on every message that arrives."""
        async with asyncio.timeout(timeout_s):
            while not done():
                self._message.clear()
                await self._message.wait()
