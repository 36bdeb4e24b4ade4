"""Waiting in tests on what a service reports (a counter, a received sample), never on wall-clock gaps."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

import pytest


async def until(cond: Callable[[], bool], what: str, timeout_s: float = 60.0) -> None:
    """Poll ``cond`` until true; fail naming ``what`` after a deadline only a hung service reaches."""
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s} s waiting for {what}")
        await asyncio.sleep(0.01)
