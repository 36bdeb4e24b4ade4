"""A grasp plan being carried out: its trajectories, the ones still planning, and the progress (pure
bookkeeping over asyncio tasks)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable
from dataclasses import dataclass, field

import numpy as np

from services.common.errors import PlanningError
from services.kinematics.trajectory import JointTrajectory
from services.task.ports import GraspPlan, SeenBox, SeenRod


@dataclass
class PlannedPick:
    """A grasp plan with a trajectory per waypoint (None: no motion) and the scene it was planned in."""

    plan: GraspPlan
    trajs: list[JointTrajectory | None]
    obstacles: tuple[SeenBox, ...]
    # the motions from waypoint ``rest_from`` on, still being planned while the arm makes the first ones
    rest: asyncio.Task[list[JointTrajectory | None]] | None = None
    rest_from: int = 0
    home: np.ndarray | None = None  # the safe home of the plan (regrasps and the way home go there)
    # waypoints moved after planning (a grasp approach retried higher): what follows them is planned
    # again from where the arm comes to rest there
    moved: set[int] = field(default_factory=set)
    # grasp approaches the controller stopped on a contact (each raised once it did)
    touched: set[int] = field(default_factory=set)
    # a rod being stood: the rod as seen, and how far off its centre it is grasped (m)
    rod: SeenRod | None = None
    grasp_offset_m: float = 0.0

    async def settle(self, seconds: float) -> None:
        """Wait for the rest of the motions (PlanningError / RobotError as planning raised them)."""
        if self.rest is None:
            return
        task, self.rest = self.rest, None
        try:
            async with asyncio.timeout(seconds):
                rest = await task
        except TimeoutError:
            raise PlanningError(
                f"planning the moves from waypoint {self.rest_from} took over {seconds:.0f} s"
            ) from None
        for i in range(self.rest_from, len(self.trajs)):
            self.trajs[i] = rest[i]

    def plan_rest(self, first: int, planning: Awaitable[list[JointTrajectory | None]]) -> None:
        """Plan the motions from waypoint ``first`` on in the background."""
        self.cancel()
        self.rest, self.rest_from = asyncio.ensure_future(planning), first

    def cancel(self) -> None:
        if self.rest is not None:
            self.rest.cancel()
            self.rest = None


@dataclass(frozen=True)
class Progress:
    """How far execution got: the waypoint under way, and whether the arm had reached it."""

    index: int = 0
    reached: bool = False
