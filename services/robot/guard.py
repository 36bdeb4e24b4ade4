"""The stop condition of a guarded move (pure): the wrist's force along a direction fell by a set amount
and stayed down for a few feedback packets (a touch-down does, a jolt of the arm does not)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from services.common.errors import InvalidInputError
from services.common.frames import finite_vector
from services.robot.feedback import FeedbackState

GUARD_DEBOUNCE_PACKETS = 3  # 24 ms of sustained force change = touch-down


def force_drop_condition(
    baseline_wrench: np.ndarray, drop_n: float, direction: list[float]
) -> Callable[[FeedbackState], bool]:
    """Stop condition of a guarded move: the force along ``direction`` fell by ``drop_n`` from
    ``baseline_wrench`` for ``GUARD_DEBOUNCE_PACKETS`` packets in a row."""
    d = finite_vector(direction or [0.0, 0.0, -1.0], 3, "force guard direction")
    norm = float(np.linalg.norm(d))
    if norm < 1e-9 or not np.isfinite(drop_n) or drop_n <= 0:
        raise InvalidInputError(
            f"force guard needs a direction and a positive force drop, got {direction}, {drop_n}"
        )
    d = d / norm
    start = float(np.dot(baseline_wrench[:3], d))
    run = 0

    def fired(fb: FeedbackState) -> bool:
        nonlocal run
        run = run + 1 if start - float(np.dot(fb.tcp_force[:3], d)) > drop_n else 0
        return run >= GUARD_DEBOUNCE_PACKETS

    return fired
