"""A service's settings, following the cell's configuration changes (PUT /config) over Zenoh.

The gateway publishes every change it accepted since it started as one patch (on each PUT and
periodically, so a service that restarts catches up). Each follower applies that patch to its own
start-up settings with the same validation the gateway used, keeps the result as ``settings`` and
calls ``on_change(new_settings, changed_paths)`` when something it holds changed.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Awaitable, Callable
from types import TracebackType

from pickplace.v1 import common_pb2

from services.common.aio import cancel_and_wait
from services.common.bus import AsyncSubscription, Bus
from services.common.config_patch import apply_patch, changed_paths, leaf_paths
from services.common.errors import InvalidInputError
from services.common.keys import CellKeys
from services.common.settings import Settings

log = logging.getLogger("pickplace.config")

OnChange = Callable[[Settings, list[str]], Awaitable[None]]


def settings_after(startup: Settings, patch_json: str) -> tuple[Settings, dict[str, object]]:
    """The start-up settings with a published patch applied; InvalidInputError naming what is wrong."""
    try:
        patch = json.loads(patch_json)
    except ValueError as exc:
        raise InvalidInputError(f"config update is not JSON: {exc}") from exc
    new, _ = apply_patch(startup, patch)
    return new, patch


def with_twin(current: Settings, new: Settings) -> Settings:
    """``current`` with the twin settings of ``new`` (a sim's own seed and ports stay as they are)."""
    return current.model_copy(update={"sim": current.sim.model_copy(update={"twin": new.sim.twin})})


class LiveConfig:
    def __init__(self, bus: Bus, settings: Settings, on_change: OnChange | None = None):
        self.startup = settings
        self.settings = settings
        self.updates_applied = 0
        self._bus = bus
        self._on_change = on_change
        self._last_patch = ""
        self._last_paths: list[str] = []
        self._sub: AsyncSubscription[common_pb2.ConfigUpdate] | None = None
        self._task: asyncio.Task[None] | None = None

    def start(self) -> LiveConfig:
        """Subscribe and follow (call from the running event loop)."""
        key = CellKeys(self.startup.cell_id).config_updates
        self._sub = self._bus.subscribe(key, common_pb2.ConfigUpdate, maxsize=8)
        self._task = asyncio.create_task(self._follow(), name="live-config")
        return self

    async def run(self) -> None:
        """Subscribe and follow until cancelled: ``start`` for a caller's own TaskGroup."""
        key = CellKeys(self.startup.cell_id).config_updates
        self._sub = self._bus.subscribe(key, common_pb2.ConfigUpdate, maxsize=8)
        try:
            await self._follow()
        finally:
            self._sub.close()
            self._sub = None

    async def stop(self) -> None:
        await cancel_and_wait(self._task)
        self._task = None
        if self._sub is not None:
            self._sub.close()
            self._sub = None

    async def __aenter__(self) -> LiveConfig:
        return self.start()

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.stop()

    async def apply(self, msg: common_pb2.ConfigUpdate) -> list[str]:
        """Take one update; the paths that changed here (none for a repeat of the last one)."""
        if msg.patch_json == self._last_patch:
            return []
        try:
            new, patch = settings_after(self.startup, msg.patch_json)
        except InvalidInputError as exc:  # the gateway validated it: a version skew, say so loudly
            log.error("configuration update refused: %s", exc)
            return []
        # what this patch sets, and what the previous one set (a key it no longer holds goes back)
        changed = changed_paths(self.settings, new, self._last_paths + leaf_paths(patch))
        self.settings = new
        self._last_patch = msg.patch_json
        self._last_paths = leaf_paths(patch)
        if changed:
            self.updates_applied += 1
            log.info("configuration changed: %s", ", ".join(changed))
            if self._on_change is not None:
                await self._on_change(new, changed)
        return changed

    async def _follow(self) -> None:
        assert self._sub is not None
        async for msg in self._sub:
            try:
                await self.apply(msg)
            except Exception:  # one bad update must not stop the following ones
                log.exception("applying a configuration update failed")
