"""Zenoh bus: a session factory that stays on loopback, and asyncio-safe pub/sub.

Zenoh invokes subscriber callbacks on its own threads; :class:`AsyncSubscription`
hands each sample to the owning event loop with ``call_soon_threadsafe`` into a
bounded queue (dropping the oldest sample when a slow consumer falls behind —
these are state streams, the newest value matters). Publishing follows the key's
:func:`~services.common.keys.lane`: every sample but the high-rate streams' (pick records,
commands, status) goes at a higher priority, in a queue of its own, so a burst of camera frames
never fills the queue a pick's outcome waits in.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator, Callable
from typing import Any, Generic, TypeVar

import zenoh
from google.protobuf.message import Message

from services.common.errors import ConfigurationError, RobotCommunicationError
from services.common.keys import Lane, lane
from services.common.settings import ZenohSettings

log = logging.getLogger("pickplace.bus")

M = TypeVar("M", bound=Message)


def zenoh_config(settings: ZenohSettings) -> zenoh.Config:
    """A Zenoh config with explicit endpoints and multicast scouting off."""
    if settings.multicast_scouting:
        raise ConfigurationError("zenoh multicast scouting must be off")
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(settings.mode))
    cfg.insert_json5("listen/endpoints", json.dumps(settings.listen))
    cfg.insert_json5("connect/endpoints", json.dumps(settings.connect))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    # Gossip only relays explicitly configured peers; keep it from wandering.
    cfg.insert_json5("scouting/gossip/enabled", "false")
    return cfg


def open_session(settings: ZenohSettings) -> zenoh.Session:
    try:
        return zenoh.open(zenoh_config(settings))
    except Exception as exc:  # zenoh raises its own ZError
        raise RobotCommunicationError(
            f"cannot open zenoh session (listen={settings.listen}, connect={settings.connect}): {exc}"
        ) from exc


class Bus:
    """A Zenoh session plus typed publish/subscribe helpers. Use as a context manager."""

    def __init__(self, settings: ZenohSettings):
        self._settings = settings
        self._session: zenoh.Session | None = None
        self._publishers: dict[str, Any] = {}

    def __enter__(self) -> Bus:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    async def __aenter__(self) -> Bus:
        await asyncio.to_thread(self.open)
        return self

    async def __aexit__(self, *exc: object) -> None:
        await asyncio.to_thread(self.close)

    def open(self) -> None:
        if self._session is not None:
            raise RuntimeError("bus already open")
        self._session = open_session(self._settings)

    def close(self) -> None:
        if self._session is None:
            return
        for pub in self._publishers.values():
            with contextlib.suppress(Exception):
                pub.undeclare()
        self._publishers.clear()
        with contextlib.suppress(Exception):
            self._session.close()
        self._session = None

    @property
    def session(self) -> zenoh.Session:
        if self._session is None:
            raise RuntimeError("bus is not open")
        return self._session

    def publish(self, key: str, message: Message | bytes) -> None:
        pub = self._publishers.get(key)
        if pub is None:
            # never BLOCK: a put that waits for room on a congested link would hold the event loop,
            # and with it the driver's ServoJ stream (the embedded cell tripped its watchdog)
            ahead = lane(key) is Lane.AHEAD
            pub = self.session.declare_publisher(
                key,
                congestion_control=zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.DATA_HIGH if ahead else zenoh.Priority.DATA,
            )
            self._publishers[key] = pub
        payload = message if isinstance(message, bytes) else message.SerializeToString()
        pub.put(payload)

    def subscribe_callback(self, key: str, callback: Callable[[str, bytes], None]) -> Any:
        """Raw subscription; ``callback(key, payload)`` runs on a Zenoh thread."""

        def _on_sample(sample: zenoh.Sample) -> None:
            try:
                callback(str(sample.key_expr), sample.payload.to_bytes())
            except Exception:  # a bad consumer must not kill zenoh's thread
                log.exception("subscriber callback for %s failed", key)

        return self.session.declare_subscriber(key, _on_sample)

    def subscribe(self, key: str, message_type: type[M], maxsize: int = 256) -> AsyncSubscription[M]:
        return AsyncSubscription(self, key, message_type, maxsize)


class AsyncSubscription(Generic[M]):
    """Async iterator over decoded messages of one key expression."""

    def __init__(self, bus: Bus, key: str, message_type: type[M], maxsize: int):
        self._loop = asyncio.get_running_loop()
        self._queue: asyncio.Queue[M] = asyncio.Queue(maxsize=maxsize)
        self._type = message_type
        self.dropped = 0
        self.decode_errors = 0
        self._sub = bus.subscribe_callback(key, self._from_zenoh_thread)

    def _from_zenoh_thread(self, key: str, payload: bytes) -> None:
        try:
            msg = self._type.FromString(payload)
        except Exception:
            self.decode_errors += 1
            log.warning("undecodable %s payload on %s (%d bytes)", self._type.__name__, key, len(payload))
            return
        with contextlib.suppress(RuntimeError):  # loop closed during shutdown
            self._loop.call_soon_threadsafe(self._put, msg)

    def _put(self, msg: M) -> None:
        if self._queue.full():
            self._queue.get_nowait()
            self.dropped += 1
        self._queue.put_nowait(msg)

    async def get(self, timeout_s: float | None = None) -> M:
        async with asyncio.timeout(timeout_s):
            return await self._queue.get()

    def __aiter__(self) -> AsyncIterator[M]:
        return self._iter()

    async def _iter(self) -> AsyncIterator[M]:
        while True:
            yield await self._queue.get()

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._sub.undeclare()
