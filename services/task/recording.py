"""The robot port that records on the outcome what a cycle executed (for the eval's bound)."""

from __future__ import annotations

import numpy as np

from services.kinematics.trajectory import JointTrajectory
from services.task.moves import joined_at
from services.task.pacing import LINE_PACE, LinePace
from services.task.pick_planning import near
from services.task.ports import GripOutcome, MoveOutcome, RobotPort
from services.task.states import PickOutcome


class RecordingRobot:
    """The robot port, recording on the outcome what the cycle executed: the joint waypoints the arm
    went through (each motion's start and its end, or where a guarded one stopped), whether it rested
    at each, the pace a guarded line went under, and the gripper actions that moved the jaws."""

    def __init__(self, robot: RobotPort, out: PickOutcome):
        self._robot, self._out = robot, out

    def __getattr__(self, name: str) -> object:
        return getattr(self._robot, name)

    async def execute(
        self, traj: JointTrajectory, force_guard_n: float = 0.0, continues: bool = False
    ) -> MoveOutcome:
        res = await self._robot.execute(traj, force_guard_n, continues=continues)
        wps, rests = self._out.executed_waypoints, self._out.executed_rests
        start = traj.positions[0]
        if not wps or not near(np.asarray(wps[-1]), start):  # within the tracking error: the same point
            wps.append([float(v) for v in start])
            rests.append(True)  # it set off from elsewhere than the last move's end: from rest
        for q in joined_at(traj):  # moves sent in one call: the arm flowed through where they meet
            wps.append([float(v) for v in q])
            rests.append(False)
        # a move that ran to its end went through its planned end (one that flows on returns while the arm
        # is still on its way, anywhere on it); one cut short ended where it stopped
        end = res.final_q if res.stopped_early else traj.positions[-1]
        wps.append([float(v) for v in end])
        rests.append(res.stopped_early or not continues)
        if force_guard_n > 0 and isinstance(pace := traj.meta.get(LINE_PACE), LinePace):
            self._out.executed_paces[len(wps) - 1] = pace  # a touch-down takes its time whatever the joints
        return res

    async def gripper(self, close: bool, release: bool = False) -> GripOutcome:
        g = await self._robot.gripper(close, release)
        if not g.unchanged:  # an open of jaws already open moved nothing and took no actuation time
            self._out.gripper_actions += 1
            self._out.gripper_releases += release
        return g
