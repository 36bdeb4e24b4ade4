"""The twin behind the simulated Dobot's TCP protocol, driven by the real DobotClient on loopback."""

from __future__ import annotations

from collections.abc import AsyncIterator

import numpy as np
import pytest

from services.common.errors import ContactAlarmError
from services.common.settings import ReconnectSettings, Settings
from services.dobot import RobotMode
from services.kinematics.robot_models import get_robot
from services.robot.client import DobotClient
from services.sim.app import build_sim_server
from services.sim.twin.trial import ScriptedArm
from tests.sim.twin_helpers import top_down_tool, twin_settings

pytestmark = pytest.mark.integration

FAST_RECONNECT = ReconnectSettings(max_attempts=3, base_delay_s=0.02, max_delay_s=0.1)


@pytest.fixture
def cell_settings() -> Settings:
    s = twin_settings({"cubes": [], "rod": False, "obstacle": False})
    # sim time runs 3x faster than wall time: same 8 ms ticks, shorter test
    return s.model_copy(update={"sim": s.sim.model_copy(update={"speed": 3.0, "engine": "twin"})})


@pytest.fixture
async def twin_server(cell_settings: Settings) -> AsyncIterator:  # type: ignore[type-arg]
    server = build_sim_server(cell_settings, "twin", ports={"dashboard": 0, "feedback": 0, "slow": 0})
    async with server:
        yield server


def client(server) -> DobotClient:  # type: ignore[no-untyped-def]
    return DobotClient(
        "127.0.0.1",
        server.ports["dashboard"],
        server.ports["feedback"],
        request_timeout_s=2.0,
        reconnect=FAST_RECONNECT,
    )


def joints_for(tool_z: float) -> np.ndarray:
    """Joint target putting the tool top-down over the pick zone at height ``tool_z``."""
    from services.sim.twin import create_twin_engine

    engine = create_twin_engine(twin_settings({"cubes": [], "rod": False, "obstacle": False}), seed=0)
    arm = ScriptedArm(engine)
    q_above = arm.path_branch([top_down_tool(0.45, 0.0, 0.15)])
    return q_above if tool_z >= 0.15 else arm.ik(top_down_tool(0.45, 0.0, tool_z), q_above)


async def test_movj_feedback_joints_are_measured_and_converge(twin_server) -> None:  # type: ignore[no-untyped-def]
    target = joints_for(0.15)
    assert get_robot("nova5").within_limits(target)
    async with client(twin_server) as c:
        await c.enable()
        rid = await c.mov_j(target, v=60)
        fb = await c.wait_motion_done(rid, 20.0)
        assert fb.robot_mode == RobotMode.ENABLE
        fb = await c.wait_feedback(lambda f: np.max(np.abs(f.q - target)) < np.deg2rad(0.05), 5.0)
        assert np.allclose(fb.q_target, target, atol=1e-6)
        # measured joints come from physics: not bit-identical to the command
        assert not np.array_equal(fb.q, fb.q_target)
        assert abs(fb.tcp_force[2]) < 0.5  # the wrist sensor is tared: nothing held


async def test_driving_into_the_table_raises_the_collision_alarm(twin_server) -> None:  # type: ignore[no-untyped-def]
    above, below = joints_for(0.15), joints_for(-0.05)
    async with client(twin_server) as c:
        await c.enable()
        rid = await c.mov_j(above, v=60)
        await c.wait_motion_done(rid, 20.0)
        rid = await c.mov_j(below, v=20)
        with pytest.raises(ContactAlarmError) as err:  # a contact, told apart from other alarms
            await c.wait_motion_done(rid, 20.0)
        assert 117 in err.value.alarms
        fb = await c.next_feedback()
        assert fb.robot_mode == RobotMode.COLLISION and fb.collision
