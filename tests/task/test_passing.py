"""The grasp check after a LIFT the arm flows on from reads the object sensor where the arm passes the
lift's end: the pure tracker, and the robot client over the robot service's joint-state stream on a
simulated controller whose object input is on only around that pose."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import numpy as np
import pytest

from services.common.grpc_util import channel
from services.common.settings import Settings
from services.kinematics.interpolation import quintic_move
from services.kinematics.robot_models import NOVA5
from services.kinematics.trajectory import JointLimits, JointTrajectory
from services.robot.service import RobotService
from services.sim.controller import SimController
from services.sim.dobot_server import SimDobotServer
from services.sim.engine import EngineState, KinematicEngine
from services.task.clients import GrpcRobot
from services.task.passing import REACHED_RAD, PassWatch
from tests.conftest import HOME

OBJECT_DI = 8


def _line(n: int, a: float, b: float) -> list[np.ndarray]:
    return [HOME + np.array([x, 0, 0, 0, 0, 0]) for x in np.linspace(a, b, n)]


def test_the_watch_fires_where_the_arm_reaches_the_pose_or_nearest_it_on_a_cut_corner():
    target = HOME + np.array([0.3, 0, 0, 0, 0, 0])
    watch = PassWatch(target)
    fired = [watch.passed(q) for q in _line(31, 0.0, 0.6)]  # through it, 0.02 rad a state
    assert fired.index(True) == 15  # the state at the pose itself
    # a rounded corner passes 0.05 rad off it: the nearest state, seen as the next one is farther
    watch = PassWatch(target)
    path = [q + np.array([0, 0.05, 0, 0, 0, 0]) for q in _line(31, 0.0, 0.6)]
    fired = [watch.passed(q) for q in path]
    # the nearest is index 15; the next is 3.9 mrad farther (jitter, as far as the watch can tell), the
    # one after 14 mrad: passed
    assert fired.index(True) == 17
    # jitter on a slow way there is no passing: it fires only once there
    watch = PassWatch(target)
    slow = [q + np.array([0, 0, 0.004 * (k % 2), 0, 0, 0]) for k, q in enumerate(_line(101, 0.25, 0.30))]
    k = [watch.passed(q) for q in slow].index(True)
    assert np.linalg.norm(slow[k] - target) <= REACHED_RAD
    # an arm that stops short, or goes by far from it, never passes it
    watch = PassWatch(target)
    assert not any(watch.passed(q) for q in [*_line(10, 0.0, 0.2), *_line(10, 0.2, 0.2)])
    watch = PassWatch(target)
    assert not any(watch.passed(q + np.array([0, 0.5, 0, 0, 0, 0])) for q in _line(31, 0.0, 0.6))


class HoldAroundThePass(KinematicEngine):
    """An ideal arm whose object input is on only while joint 1 is within 2° of ``around``: read
    anywhere else along the motion, the sensor says "empty"."""

    around = np.inf

    def state(self) -> EngineState:
        st = super().state()
        near = abs(st.q[0] - self.around) <= np.deg2rad(2.0)
        st.digital_inputs = (1 << (OBJECT_DI - 1)) if near else 0
        return st


@pytest.fixture
async def robot(settings: Settings) -> AsyncIterator[tuple[GrpcRobot, HoldAroundThePass]]:
    engine = HoldAroundThePass(HOME)
    ctrl = SimController(NOVA5, engine, q0=HOME)
    async with SimDobotServer(ctrl, "127.0.0.1", 0, 0, None) as sim:
        s = settings.model_copy(
            update={
                "robot": settings.robot.model_copy(
                    update={"dashboard_port": sim.ports["dashboard"], "feedback_port": sim.ports["feedback"]}
                ),
                "gripper": settings.gripper.model_copy(update={"object_di": OBJECT_DI}),
            }
        )
        async with RobotService(s, None, grpc_port=0) as svc, channel("127.0.0.1", svc.grpc_port) as ch:
            from pickplace.v1 import robot_pb2_grpc

            client = GrpcRobot(robot_pb2_grpc.RobotControllerStub(ch), s)
            await client.recover()
            yield client, engine


def _two_segments(period: float) -> tuple[JointTrajectory, JointTrajectory]:
    """40° of joint 1 from rest to rest, cut half way (on the streaming period): the first ends in motion."""
    lim = JointLimits.from_spec(NOVA5, 0.5, 0.5)
    whole = quintic_move(
        HOME, HOME + np.deg2rad([40.0, 0, 0, 0, 0, 0]), joint_names=NOVA5.joint_names, limits=lim
    )
    t_cut = round(whole.duration / 2 / period) * period
    ts = np.arange(0.0, whole.duration + 1e-9, 0.01)
    first = np.union1d(ts[ts < t_cut], [t_cut])
    second = np.union1d(ts[ts > t_cut], [t_cut, whole.duration])
    pieces = []
    for t in (first, second):
        q, qd, qdd = whole.sample(t)
        pieces.append(JointTrajectory(whole.joint_names, t - t[0], q, qd, qdd))
    return pieces[0], pieces[1]


@pytest.mark.integration
async def test_the_robot_client_reads_the_sensor_as_the_arm_passes_the_pose(
    robot: tuple[GrpcRobot, HoldAroundThePass], settings: Settings
) -> None:
    client, engine = robot
    first, second = _two_segments(settings.robot.servo_period_s)
    engine.around = first.positions[-1][0]
    assert np.any(first.velocities[-1] != 0)
    # answered with targets still queued ahead of the arm: read now, the sensor would say "empty"
    await client.execute(first, continues=True)
    check = asyncio.ensure_future(client.holding_on_passing(first.positions[-1]))
    await client.execute(second)  # at rest at the end: far past the pose, the input off again
    assert await check is True  # read where the arm passed it
    assert await client.holding() is False
