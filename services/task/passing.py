"""When the arm passes a pose, from the joint states the controller reports (pure): a blended motion
flows through its waypoints (within its rounded corners), so "reached" is the first state within
:data:`REACHED_RAD` of the pose, or, once the arm has come within :data:`NEAR_RAD` of it, the first
that is :data:`AWAY_RAD` farther than the nearest one."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

REACHED_RAD = np.deg2rad(0.5)  # this near in joint space: there
# a rounded corner passes its waypoint at up to half its rounding (0.3 rad at most: 8.6°) in joint space
NEAR_RAD = np.deg2rad(12.0)
AWAY_RAD = np.deg2rad(0.5)  # moving away by more than the states' jitter: past the nearest point


@dataclass
class PassWatch:
    """Feed it the arm's joint states in order; :meth:`passed` answers True at the state where the arm
    passes ``target`` (by the joint-space distance)."""

    target: np.ndarray
    nearest: float = math.inf

    def passed(self, q: np.ndarray) -> bool:
        d = float(np.linalg.norm(np.asarray(q, dtype=float) - self.target))
        if d <= REACHED_RAD or (self.nearest <= NEAR_RAD and d > self.nearest + AWAY_RAD):
            return True
        self.nearest = min(self.nearest, d)
        return False
