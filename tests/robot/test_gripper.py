"""The DO gripper over the wire, timed on the controller's clock: a simulated controller that runs
slower than the wall (a busy machine) must not shorten any of its waits."""

import contextlib
from collections.abc import AsyncIterator

import numpy as np
import pytest

from services.common.settings import GripperSettings
from services.kinematics.robot_models import NOVA5
from services.robot.client import DobotClient
from services.robot.feedback import FeedbackState
from services.robot.gripper import EMPTY_CLOSE_FACTOR, DigitalOutputGripper
from services.sim.controller import SimController
from services.sim.dobot_server import SimDobotServer
from services.sim.engine import EngineState, KinematicEngine
from tests.conftest import HOME

pytestmark = pytest.mark.integration

OBJECT_DI = 8
SLOW_SPEED = 0.25  # sim seconds per wall second: the old wall-clock waits saw a quarter of the jaw travel


class FingerEngine(KinematicEngine):
    """Ideal arm; the object input comes on ``grip_after_s`` of sim time after the close DO (never
    when ``grip_after_s`` is None: nothing between the jaws)."""

    def __init__(self, grip_after_s: float | None):
        super().__init__(HOME)
        self.grip_after_s = grip_after_s
        self._closed_for: float | None = None

    def set_digital_outputs(self, outputs: int) -> None:
        super().set_digital_outputs(outputs)
        closed = bool(outputs & 1)
        self._closed_for = (self._closed_for or 0.0) if closed else None

    def step(self, dt: float, q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray) -> EngineState:
        super().step(dt, q_ref, qd_ref, qdd_ref)
        if self._closed_for is not None:
            self._closed_for += dt
        return self.state()

    def state(self) -> EngineState:
        st = super().state()
        held = (
            self.grip_after_s is not None
            and self._closed_for is not None
            and self._closed_for >= self.grip_after_s
        )
        st.digital_inputs = (1 << (OBJECT_DI - 1)) if held else 0
        return st


@contextlib.asynccontextmanager
async def _cell(
    grip_after_s: float | None, object_di: int | None
) -> AsyncIterator[tuple[SimDobotServer, DobotClient, DigitalOutputGripper]]:
    ctrl = SimController(NOVA5, FingerEngine(grip_after_s), q0=HOME)
    async with contextlib.AsyncExitStack() as stack:
        sim = await stack.enter_async_context(SimDobotServer(ctrl, "127.0.0.1", 0, 0, None, speed=SLOW_SPEED))
        client = await stack.enter_async_context(
            DobotClient("127.0.0.1", sim.ports["dashboard"], sim.ports["feedback"])
        )
        await client.enable()
        settings = GripperSettings(close_do=1, open_do=2, object_di=object_di, actuation_time_s=0.4)
        yield sim, client, DigitalOutputGripper(client, settings)


def _first_stamp_with_do(client: DobotClient, bit: int) -> list[int]:
    """Record the controller stamp of the first packet that shows DO ``bit`` on."""
    seen: list[int] = []

    def on_packet(fb: FeedbackState) -> None:
        if not seen and fb.digital_outputs >> (bit - 1) & 1:
            seen.append(fb.timestamp_ms)

    client.add_listener(on_packet)
    return seen


async def test_close_on_the_rod_is_seen_on_a_slow_controller():
    # the fingers reach the rod after 0.35 s of controller time (the twin: 0.32–0.43 s for 0.4 s)
    async with _cell(grip_after_s=0.35, object_di=OBJECT_DI) as (_sim, _client, gripper):
        state = await gripper.close()
        assert state.closed and state.object_detected is True


async def test_close_on_nothing_waits_its_controller_time_then_says_so():
    async with _cell(grip_after_s=None, object_di=OBJECT_DI) as (_sim, client, gripper):
        closed_at = _first_stamp_with_do(client, 1)
        state = await gripper.close()
        assert state.object_detected is False
        assert client.feedback is not None and closed_at
        assert client.feedback.timestamp_ms - closed_at[0] >= EMPTY_CLOSE_FACTOR * 0.4 * 1000


async def test_without_a_sensor_close_and_open_take_the_actuation_time_of_controller_time():
    async with _cell(grip_after_s=0.1, object_di=None) as (_sim, client, gripper):
        closed_at = _first_stamp_with_do(client, 1)
        state = await gripper.close()
        assert state.closed and state.object_detected is None
        assert client.feedback is not None and closed_at
        assert client.feedback.timestamp_ms - closed_at[0] >= 400
        opened_at = _first_stamp_with_do(client, 2)
        await gripper.open()
        assert opened_at and client.feedback.timestamp_ms - opened_at[0] >= 400


async def test_an_open_gripper_is_not_opened_again():
    async with _cell(grip_after_s=0.1, object_di=None) as (sim, _client, gripper):
        await gripper.open()
        handled = sim.controller.commands_handled
        state = await gripper.open()
        assert not state.closed and state.unchanged
        assert sim.controller.commands_handled == handled and gripper.opens_skipped == 1
        assert not (await gripper.close()).unchanged
        assert sim.controller.commands_handled > handled  # a close is always sent
        await gripper.open()
        assert gripper.opens_skipped == 1  # after a close, an open is sent again


async def test_a_release_answers_once_the_jaws_let_go_and_the_next_open_waits_out_the_stroke():
    async with _cell(grip_after_s=0.1, object_di=None) as (sim, client, gripper):
        await gripper.close()
        opened_at = _first_stamp_with_do(client, 2)
        state = await gripper.open(release=True)
        assert client.feedback is not None and opened_at and not state.closed
        released_ms = client.feedback.timestamp_ms - opened_at[0]
        # clear of the object (release_time_s, default 0.12 s), well before the 0.4 s stroke is over
        assert 120 <= released_ms < 400
        handled = sim.controller.commands_handled
        await gripper.open()  # the jaws are opening already: nothing sent, the rest of the stroke waited
        assert sim.controller.commands_handled == handled and gripper.opens_skipped == 1
        assert client.feedback.timestamp_ms - opened_at[0] >= 400
