"""The stop condition of a guarded move (pure): the wrist's force along a direction fell by a set amount
and stayed down for a few feedback packets (a touch-down does, a jolt of the arm does not)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from services.common.errors import InvalidInputError
from services.common.frames import finite_vector
from services.robot.feedback import FeedbackState

GUARD_DEBOUNCE_PACKETS = 3  # 24 ms of sustained force change = touch-down
PEAK_FRACTION = 0.999  # a speed this close to the top is the top (a steady descent's rounding)
# a speed-up gentler than this lightens the wrist by under 0.4 N (0.8 N was seen at 1 m/s², seed 1575):
# below the 0.6 N guard, so the guard watches through it
SPEED_UP_ACCEL_M_S2 = 0.5


def speed_up_length(tool_positions: np.ndarray, times: np.ndarray, direction: list[float]) -> float:
    """How far along ``direction`` a guarded move's tool goes before its commanded speed-up is over
    (``tool_positions`` (N, 3) at the knot ``times``): up to its first top speed, counting only the
    acceleration that lightens the wrist noticeably (over ``SPEED_UP_ACCEL_M_S2``). While it speeds up
    downward the tool's own inertia lightens the wrist as a touch-down does: seen 0.8 N on average under
    the 1 m/s² of a paced touch-down, with 1.4 N peaks each ServoJ step, against a 0.6 N guard (seed 1575
    stopped 28 mm above the table and dropped the rod). A descent that is slow from its start (a touch-down
    taken further, seed 1007: 0.25 m/s² up to 50 mm/s) is watched from its first millimetre: unarmed for
    its 5 mm speed-up it pushed the rod 3 mm into the table, and 12 N, before the guard fired."""
    p = np.asarray(tool_positions, dtype=float)
    t = np.asarray(times, dtype=float)
    if len(p) < 2:
        return 0.0
    d = _unit(direction)
    along = (p - p[0]) @ d
    dt = np.maximum(np.diff(t), 1e-9)
    speed = np.diff(along) / dt  # over each knot interval
    peak = float(np.max(speed))
    if peak <= 0:
        return 0.0
    top = int(np.argmax(speed >= PEAK_FRACTION * peak))  # the first interval at top speed
    # the acceleration from interval j to j + 1, for the intervals before the top
    accel = np.diff(speed[: top + 1]) / np.maximum(0.5 * (dt[:top] + dt[1 : top + 1]), 1e-9)
    felt = np.flatnonzero(accel > SPEED_UP_ACCEL_M_S2)
    if len(felt) == 0:
        return 0.0
    return float(max(along[felt[-1] + 2], 0.0))  # the end of the interval that acceleration led into


def force_drop_condition(
    baseline_wrench: np.ndarray, drop_n: float, direction: list[float], arm_after_m: float = 0.0
) -> Callable[[FeedbackState], bool]:
    """Stop condition of a guarded move: the force along ``direction`` fell by ``drop_n`` from
    ``baseline_wrench`` for ``GUARD_DEBOUNCE_PACKETS`` packets in a row, once the tool has gone
    ``arm_after_m`` along ``direction`` from where the first packet saw it (see :func:`speed_up_length`)."""
    d = _unit(direction)
    if not np.isfinite(drop_n) or drop_n <= 0:
        raise InvalidInputError(
            f"force guard needs a direction and a positive force drop, got {direction}, {drop_n}"
        )
    if not np.isfinite(arm_after_m):
        raise InvalidInputError(f"force guard arming distance must be finite, got {arm_after_m}")
    start = float(np.dot(baseline_wrench[:3], d))
    run = 0
    p0: np.ndarray | None = None
    armed = arm_after_m <= 0

    def fired(fb: FeedbackState) -> bool:
        nonlocal run, p0, armed
        if not armed:
            p = fb.T_base_tool[:3, 3]
            if p0 is None:
                p0 = p.copy()
            armed = float(np.dot(p - p0, d)) >= arm_after_m
            if not armed:
                return False
        run = run + 1 if start - float(np.dot(fb.tcp_force[:3], d)) > drop_n else 0
        return run >= GUARD_DEBOUNCE_PACKETS

    return fired


def _unit(direction: list[float]) -> np.ndarray:
    d = finite_vector(direction or [0.0, 0.0, -1.0], 3, "force guard direction")
    norm = float(np.linalg.norm(d))
    if norm < 1e-9:
        raise InvalidInputError(f"force guard needs a direction, got {direction}")
    return d / norm
