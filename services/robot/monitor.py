"""Execution monitoring and the ServoJ feed watchdog (pure: fed feedback states, no I/O).

A :class:`StreamMonitor` follows one ServoJ stream — a trajectory, or a chain of trajectories that
continue into each other — packet by packet:

- **path**: the measured joints are compared with the planned targets around the one the controller
  is executing (its CurrentCommandId), allowing ``lag_targets`` periods of tracking lag; a joint
  further than the path tolerance from the plan is a fault naming the joint and the deviation.
- **feed**: while the host still owes targets (mid-stream, or a continuing trajectory whose successor
  has not come), the controller must never run dry: once it is executing the newest target sent, the
  stream is starved after that target's period plus ``feed_margin_s``. Starvation is judged on both
  clocks — the controller's (the arm really is waiting) and the host's (the host really is late), so
  a simulator running N× faster than the wall is not mistaken for a stalled host, and a host whose
  event loop froze is not excused by the packets that queued meanwhile.

A :class:`MoveMonitor` does the path part for a controller-planned move (MovJ / MovL): measured
joints against the controller's own reference (QTarget). :func:`goal_deviation` is the goal check.
The driver (:mod:`services.robot.driver`) stops the arm when a monitor trips.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from services.common.errors import ExecutionError, PathDeviationError
from services.dobot import RobotMode
from services.robot.feedback import FeedbackState

LAG_TARGETS = 2  # periods of tracking lag the path check allows (a servo trails its reference)


@dataclass(frozen=True)
class Deviation:
    joint: int  # 0-based
    rad: float  # signed: measured minus plan

    def describe(self) -> str:
        return f"joint {self.joint + 1} is {np.rad2deg(self.rad):+.2f}° off"


def _largest(d: np.ndarray) -> Deviation:
    j = int(np.argmax(np.abs(d)))
    return Deviation(j, float(d[j]))


def path_deviation(q: np.ndarray, points: list[np.ndarray]) -> Deviation:
    """The deviation of ``q`` from the polyline through ``points`` (its closest segment, judged by the
    largest joint error)."""
    if len(points) == 1:
        return _largest(q - points[0])
    best: Deviation | None = None
    for a, b in itertools.pairwise(points):
        ab = b - a
        n2 = float(ab @ ab)
        u = 0.0 if n2 <= 0 else min(1.0, max(0.0, float((q - a) @ ab) / n2))
        dev = _largest(q - (a + u * ab))
        if best is None or abs(dev.rad) < abs(best.rad):
            best = dev
    assert best is not None
    return best


def goal_deviation(q: np.ndarray, goal: np.ndarray) -> Deviation:
    return _largest(np.asarray(q, dtype=float) - np.asarray(goal, dtype=float))


class StreamMonitor:
    """One ServoJ stream, fed every sound feedback packet; it trips once (``fault``, ``on_trip``)."""

    def __init__(
        self,
        q_start: np.ndarray,
        period_s: float,
        path_tolerance_rad: float,
        feed_margin_s: float,
        on_trip: Callable[[ExecutionError], None] | None = None,
        wall_s: Callable[[], float] = time.monotonic,
    ):
        self.period_s = period_s
        self.path_tolerance_rad = path_tolerance_rad
        self.feed_margin_s = feed_margin_s
        self.on_trip = on_trip
        self._wall_s = wall_s
        self._points: list[np.ndarray] = [np.asarray(q_start, dtype=float).copy()]
        self._ids: list[int | None] = []  # the queue ID of each target (points[i + 1])
        self._t_s: list[float] = []  # each target's ServoJ ``t``
        # the segment: the targets since the stream last started from rest; the controller cannot have
        # started its first before ``_anchor_ms`` (a packet that came before it did), and executes its
        # targets back to back at best, so it cannot run dry before the anchor plus their ``t``s
        self._segment = 0  # targets sent before the segment
        self._anchor_ms: float | None = None
        self._segment_s = 0.0
        self._done = 0  # targets (from the oldest kept) the controller has started
        self._dropped = 0  # targets pruned from the front (executed long ago)
        self.owed = True  # the host still owes targets: the controller must not run dry
        self.ends_slowed = False  # resumed from rest, the stream ends slower than planned (at rest)
        self.fault: ExecutionError | None = None
        self.max_path_deviation_rad = 0.0
        self._starved_at: tuple[int, float] | None = None  # (controller ms, host s) of running dry

    # ------------------------------------------------------------------ the host's side
    def sent(self, q: np.ndarray, rid: int | None, stamp_ms: int | None = None) -> None:
        """A target left (``stamp_ms``: the controller clock of the newest packet before it did)."""
        if self.targets_sent == self._segment and stamp_ms is not None:
            self._anchor_ms = float(stamp_ms)
        self._points.append(np.asarray(q, dtype=float).copy())
        self._ids.append(rid)
        self._t_s.append(self.period_s)
        self._segment_s += self.period_s
        self._starved_at = None

    def from_rest(self) -> None:
        """The stream starts again from rest (the controller ran dry and holds the last target)."""
        self._segment = self.targets_sent
        self._anchor_ms = None
        self._segment_s = 0.0

    def dry_at_ms(self, fb: FeedbackState) -> float:
        """The earliest controller time at which the controller can have run out of the targets sent: the
        packet's stamp plus the ``t`` of those it had not started, or the segment's anchor plus the ``t``
        of all its targets (executed back to back), whichever is later. A lower bound: a target that
        arrives late only delays the rest."""
        k = self._executing(fb.current_command_id)
        held = fb.timestamp_ms + 1000.0 * sum(self._t_s[k + 1 :])
        if self._anchor_ms is None:
            return held
        return max(held, self._anchor_ms + 1000.0 * self._segment_s)

    def tail(self) -> np.ndarray:
        """The last two positions of the stream (the start twice when nothing was sent), oldest first."""
        return np.vstack(self._points[-2:] if len(self._points) > 1 else self._points * 2)

    @property
    def targets_sent(self) -> int:
        return self._dropped + len(self._ids)

    def unstarted(self, current_id: int) -> int:
        """Targets sent that the controller has not started yet: the look-ahead it holds, across the
        whole chain (a continuing trajectory's tail counts for the next one's flow control)."""
        self._executing(current_id)
        return len(self._ids) - self._done

    # ------------------------------------------------------------------ the controller's side
    def _executing(self, current_id: int) -> int:
        """Index (into the kept targets) of the newest one the controller has started, -1 if none."""
        while self._done < len(self._ids):
            rid = self._ids[self._done]
            if rid is None or rid > current_id:
                break
            self._done += 1
        return self._done - 1

    def on_feedback(self, fb: FeedbackState) -> ExecutionError | None:
        if self.fault is not None:
            return self.fault
        k = self._executing(fb.current_command_id)
        if self._anchor_ms is not None and self._dropped + k < self._segment:
            self._anchor_ms = max(self._anchor_ms, float(fb.timestamp_ms))  # its first not started yet
        if self._ids and all(r is not None for r in self._ids):
            lo = max(0, k - LAG_TARGETS)
            dev = path_deviation(fb.q, self._points[lo : k + 2])
            self.max_path_deviation_rad = max(self.max_path_deviation_rad, abs(dev.rad))
            if abs(dev.rad) > self.path_tolerance_rad:
                n = self.targets_sent
                return self._trip(
                    PathDeviationError(
                        f"execution monitor: {dev.describe()} the planned trajectory at step "
                        f"{self._dropped + k + 1}/{n} (path tolerance "
                        f"{np.rad2deg(self.path_tolerance_rad):.2f}°); arm stopped"
                    )
                )
        starved = self.owed and bool(self._ids) and k == len(self._ids) - 1
        # idle with targets not started: the controller ended the stream (its own watchdog, a Stop)
        dropped = fb.robot_mode == RobotMode.ENABLE and k < len(self._ids) - 1
        if starved or dropped:
            now = self._wall_s()
            if self._starved_at is None:
                self._starved_at = (fb.timestamp_ms, now)
            else:
                bound_s = self.period_s + self.feed_margin_s
                ms0, wall0 = self._starved_at
                if fb.timestamp_ms - ms0 >= bound_s * 1000.0 and now - wall0 >= bound_s:
                    n = self.targets_sent
                    return self._trip(
                        ExecutionError(
                            f"ServoJ watchdog: the stream was not fed for {(fb.timestamp_ms - ms0) / 1000:.3f} s "
                            f"of controller time after its last target (bound {bound_s:.3f} s: the "
                            f"period plus {self.feed_margin_s:.3f} s); arm stopped"
                        )
                        if starved
                        else ExecutionError(
                            f"the controller ended the ServoJ stream at step {self._dropped + k + 1}/{n}: it "
                            "is idle with targets not started (its own watchdog, or a Stop from elsewhere)"
                        )
                    )
        else:
            self._starved_at = None
        self._prune()
        return None

    def _prune(self) -> None:
        cut = self._done - LAG_TARGETS - 1
        if cut > 64:
            del self._points[:cut]
            del self._ids[:cut]
            del self._t_s[:cut]
            self._done -= cut
            self._dropped += cut

    def _trip(self, fault: ExecutionError) -> ExecutionError:
        self.fault = fault
        if self.on_trip is not None:
            self.on_trip(fault)
        return fault


class MoveMonitor:
    """A controller-planned move: the measured joints against the controller's reference (QTarget)."""

    def __init__(self, path_tolerance_rad: float, on_trip: Callable[[ExecutionError], None] | None = None):
        self.path_tolerance_rad = path_tolerance_rad
        self.on_trip = on_trip
        self.fault: ExecutionError | None = None
        self.max_path_deviation_rad = 0.0

    def on_feedback(self, fb: FeedbackState) -> ExecutionError | None:
        if self.fault is not None:
            return self.fault
        dev = goal_deviation(fb.q, fb.q_target)
        self.max_path_deviation_rad = max(self.max_path_deviation_rad, abs(dev.rad))
        if abs(dev.rad) > self.path_tolerance_rad:
            self.fault = PathDeviationError(
                f"execution monitor: {dev.describe()} the controller's reference (path tolerance "
                f"{np.rad2deg(self.path_tolerance_rad):.2f}°); arm stopped"
            )
            if self.on_trip is not None:
                self.on_trip(self.fault)
        return self.fault


class ClockRate:
    """How fast the controller's clock runs against the host's (a simulator at N×, or slowed by a busy
    machine): from packets at least ``window_s`` of host time apart. 1.0 until there are enough."""

    def __init__(self, window_s: float = 1.0):
        self.window_s = window_s
        self._samples: list[tuple[int, int]] = []  # (controller ms, host receipt ns), oldest first
        self.rate = 1.0

    def on_feedback(self, stamp_ms: int, received_ns: int) -> float:
        if not self._samples or received_ns - self._samples[-1][1] >= 0.1e9:
            self._samples.append((stamp_ms, received_ns))
        while len(self._samples) > 2 and received_ns - self._samples[1][1] >= self.window_s * 1e9:
            self._samples.pop(0)
        ms0, ns0 = self._samples[0]
        if received_ns - ns0 >= self.window_s * 1e9 / 2:
            self.rate = min(max((stamp_ms - ms0) / ((received_ns - ns0) / 1e6), 0.1), 100.0)
        return self.rate
