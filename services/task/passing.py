"""When the arm passes a pose, from the joint states the controller reports (pure): a blended motion
flows through its waypoints (within its rounded corners), so "reached" is the first state within
:data:`REACHED_RAD` of the pose, or the nearest one once the arm moves away again."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

REACHED_RAD = np.deg2rad(0.5)  # this near in joint space: there
NEAR_RAD = np.deg2rad(6.0)  # the nearest state counts as passing only this near (a rounded corner's cut)


@dataclass
class PassWatch:
    """Feed it the arm's joint states in order; :meth:`passed` answers True at the state where the arm
    passes ``target`` (by the joint-space distance)."""

    target: np.ndarray
    nearest: float = math.inf

    def passed(self, q: np.ndarray) -> bool:
        d = float(np.linalg.norm(np.asarray(q, dtype=float) - self.target))
        if d <= REACHED_RAD or (self.nearest <= NEAR_RAD and d > self.nearest):
            return True
        self.nearest = min(self.nearest, d)
        return False
