"""The set-off under way: sent in pieces (:mod:`services.task.flow_on`), and once the grasp plan is in,
flowing on down the grasp line from where the arm will be instead of stopping above the object — when
that way on is planned before the piece it continues has gone out. Otherwise the set-off ends at rest
as planned, and the cycle goes on from there as before."""

from __future__ import annotations

import asyncio
import logging

import numpy as np

from services.common.errors import ContinuationLateError, StartMismatchError
from services.kinematics.trajectory import JointTrajectory
from services.task.flow_on import Cut, cut_after, pieces
from services.task.pick_planning import PickPlanning, SetOffMove
from services.task.planned import PlannedPick
from services.task.ports import MoveOutcome, RobotPort

log = logging.getLogger("pickplace.task.set_off")

WayOn = tuple[JointTrajectory, int]  # the motion, and the waypoint it ends at


class SetOffRun:
    """One set-off: the move, where it starts and ends, its pieces, and where it went on to."""

    def __init__(self, move: SetOffMove, start: np.ndarray, period_s: float, flows_on: bool):
        self.move, self.start = move, start
        self.end = move.traj.positions[-1]
        self.parts = pieces(move.traj, period_s) if flows_on else [move.traj]
        self.in_flight = -1  # the piece being sent (the call under way)
        self.went_on_to: int | None = None  # the waypoint the arm went on to without stopping
        self._way_on: asyncio.Future[tuple[Cut, WayOn | None]] | None = None
        self._way_on_index = -1  # the piece whose end it is planned from
        self._plan: tuple[PickPlanning, PlannedPick] | None = None

    def flow_on(self, planning: PickPlanning, planned: PlannedPick) -> None:
        """The grasp plan is in: plan the way on from the end of the piece after the one being sent
        (planning it takes 0.03-0.15 s on a busy 2-core machine, a piece 0.06 s)."""
        if len(self.parts) > 1:
            self._plan = (planning, planned)
            self._plan_way_on(self.in_flight + 1)

    def _plan_way_on(self, index: int) -> None:
        cut = cut_after(self.parts, max(index, 0))
        if cut is None or self._plan is None:
            self._way_on = None
            return
        planning, planned = self._plan
        self._way_on_index = cut.index
        self._way_on = asyncio.ensure_future(self._way_on_from(planning, planned, cut))

    async def _way_on_from(
        self, planning: PickPlanning, planned: PlannedPick, c: Cut
    ) -> tuple[Cut, WayOn | None]:
        return c, await planning.way_on(planned, self.move, c.q, c.qd)

    def _ready(self, index: int) -> WayOn | None:
        """The way on from the end of piece ``index`` (just gone out), if it is planned by now; if it is
        still being planned it comes too late, and is planned again from the end of the piece after
        the next (the next goes out meanwhile)."""
        task = self._way_on
        if task is None:
            return None
        if not task.done():
            if self._way_on_index == index:
                task.cancel()
                log.debug("the way on from the set-off's piece %d is late: from the next one's", index)
                self._plan_way_on(index + 2)
            return None
        if task.cancelled() or (exc := task.exception()) is not None:
            if not task.cancelled():
                log.warning("planning the way on from the set-off failed: %r", exc)
            self._way_on = None
            return None
        cut, way = task.result()
        return way if cut.index == index else None

    def cancel(self) -> None:
        if self._way_on is not None:
            self._way_on.cancel()
            self._way_on = None

    async def run(self, robot: RobotPort) -> MoveOutcome:
        """Send the pieces, each flowing on into the next, or into the way on once it is ready."""
        try:
            return await self._run(robot)
        finally:
            self.cancel()

    async def _run(self, robot: RobotPort) -> MoveOutcome:
        last = len(self.parts) - 1
        for k, part in enumerate(self.parts):
            self.in_flight = k
            try:
                res = await robot.execute(part, continues=k < last)
            except (ContinuationLateError, StartMismatchError) as exc:
                if k == 0:
                    raise
                return await self._rested(robot, exc)
            if k == last:
                return res
            way = self._ready(k)
            if way is not None:
                traj, index = way
                self.went_on_to = index
                try:
                    return await robot.execute(traj)
                except (ContinuationLateError, StartMismatchError) as exc:
                    self.went_on_to = None
                    return await self._rested(robot, exc)
        raise AssertionError("unreachable: the last piece returns")

    async def _rested(self, robot: RobotPort, exc: Exception) -> MoveOutcome:
        """The piece before ran out before the next came (a busy machine): nothing more was sent and the
        arm rests on its way; the cycle moves it on to the grasp's approach from there."""
        log.info("the set-off rests short of its end: %s", exc)
        return MoveOutcome(await robot.joints(), 0.0)
