"""The task's plans on the bus (``TaskPlan`` on ``keys.task_plans``): what the task service publishes for the
live view and the recorder, and that a plan which cannot be published still reaches the cycle."""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
import pytest
from pickplace.v1 import task_pb2

from services.common.modes import MotionKind
from services.common.settings import load_settings
from services.kinematics.analytic import solve_nearest
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_frame
from services.kinematics.trajectory import JointTrajectory
from services.task.ports import Move, SeenBox
from services.task.runner import PublishedPlans

NAMES = tuple(f"joint{i + 1}" for i in range(6))
Q_START = np.deg2rad([0.0, 0.0, 90.0, 0.0, -90.0, 0.0])


def straight(q0: np.ndarray, q1: np.ndarray, n: int = 5) -> JointTrajectory:
    s = np.linspace(0.0, 1.0, n)[:, None]
    return JointTrajectory(
        NAMES, np.linspace(0.0, 1.0, n), q0 + s * (q1 - q0), np.zeros((n, 6)), np.zeros((n, 6))
    )


class Motion:
    """Plans a straight joint line to where the tool reaches ``target`` (the arm's own IK), or nothing."""

    def __init__(self, q_goal: np.ndarray):
        self.q_goal = q_goal
        self.calls = 0

    async def plan_moves(
        self,
        start: np.ndarray,
        moves: Sequence[Move],
        obstacles: tuple[SeenBox, ...],
        start_velocity: np.ndarray | None = None,
    ) -> list[JointTrajectory | None]:
        self.calls += 1
        return [straight(start, self.q_goal), None][: len(moves)]

    async def tool_pose(self, q: np.ndarray) -> np.ndarray:
        return np.eye(4)


def box(lo: list[float], hi: list[float]) -> SeenBox:
    return SeenBox(np.array(lo), np.array(hi))


async def test_a_plan_is_published_as_the_tool_tips_path_and_the_boxes_it_was_planned_around() -> None:
    s = load_settings("sim", overrides={"logging": {"file": None}})
    spec, T_flange_tool = get_robot(s.robot.model), tool_frame(s)
    T_base_tool = np.eye(4)
    T_base_tool[:3, :3] = np.diag([1.0, -1.0, -1.0])  # tool pointing down
    T_base_tool[:3, 3] = [0.45, 0.10, 0.20]
    q_goal = solve_nearest(spec, T_base_tool @ np.linalg.inv(T_flange_tool), Q_START)
    published: list[task_pb2.TaskPlan] = []
    plans = PublishedPlans(Motion(q_goal), s, published.append)
    plans.cycle_index = 7
    obstacle = box([0.3, -0.1, 0.0], [0.4, 0.0, 0.1])
    placed = box([0.6, 0.4, 0.0], [0.65, 0.45, 0.05])
    moves = [
        Move(MotionKind.LINEAR, T_base_tool, label="APPROACH", obstacles=(placed,)),
        Move(MotionKind.JOINT, q_goal, label="HOLD", obstacles=(obstacle,)),
    ]
    planned = await plans.plan_moves(Q_START, moves, (obstacle,))
    assert planned[0] is not None and planned[1] is None  # the cycle gets motion's answer as it was
    (msg,) = published
    # through the wire, as the recorder gets it
    msg = task_pb2.TaskPlan.FromString(msg.SerializeToString())
    assert msg.cycle_index == 7 and msg.label == "APPROACH+HOLD" and msg.header.frame_id == "base"
    path = np.array([(p.x, p.y, p.z) for p in msg.tool_path])
    assert path.shape == (5, 3)  # one point per knot of the trajectories that move the arm
    np.testing.assert_allclose(path[-1], T_base_tool[:3, 3], atol=1e-6)  # the tool tip where IK put it
    # the boxes of the plan's scene and each move's own, each once
    boxes = sorted((b.x_min, b.y_min, b.z_min, b.x_max, b.y_max, b.z_max) for b in msg.boxes)
    assert boxes == [(0.3, -0.1, 0.0, 0.4, 0.0, 0.1), (0.6, 0.4, 0.0, 0.65, 0.45, 0.05)]
    await plans.plan_moves(Q_START, moves, (obstacle,))
    assert [m.header.seq for m in published] == [1, 2]


async def test_a_plan_that_cannot_be_published_still_reaches_the_cycle(
    caplog: pytest.LogCaptureFixture,
) -> None:
    s = load_settings("sim", overrides={"logging": {"file": None}})

    def broken(_msg: task_pb2.TaskPlan) -> None:
        raise ConnectionError("the Zenoh session is closed")

    motion = Motion(Q_START + 0.1)
    plans = PublishedPlans(motion, s, broken)
    with caplog.at_level(logging.WARNING, logger="pickplace.task.runner"):
        planned = await plans.plan_moves(Q_START, [Move(MotionKind.JOINT, Q_START + 0.1, label="A")], ())
    assert motion.calls == 1 and planned[0] is not None
    np.testing.assert_allclose(planned[0].positions[-1], Q_START + 0.1)
    assert any("publishing a plan failed" in r.getMessage() for r in caplog.records)
