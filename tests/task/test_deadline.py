"""Deadlines on the controller's clock (services/task/deadline.py), judged by fake clocks."""

from __future__ import annotations

import asyncio

import pytest

from services.common.errors import RobotError
from services.task.deadline import within


class Clock:
    """A clock that moves by ``step`` every time it is read."""

    def __init__(self, step: float) -> None:
        self.t, self.step = 0.0, step

    def __call__(self) -> float:
        self.t += self.step
        return self.t


async def _never() -> None:
    await asyncio.Event().wait()


async def _value() -> int:
    return 7


async def test_a_finished_wait_returns_its_value() -> None:
    assert await within(_value(), 1.0, "x", Clock(0.0)) == 7


async def test_the_deadline_runs_out_on_the_controller_clock_not_the_wall_clock() -> None:
    controller = Clock(1.0)  # the controller's clock runs far ahead of the wall clock
    with pytest.raises(RobotError, match="motion to GRASP did not finish within its 3 s deadline"):
        await within(_never(), 3.0, "motion to GRASP", controller, wall_clock=Clock(0.0), poll_s=0.001)


async def test_a_clock_that_stands_still_is_caught_by_the_wall_backstop() -> None:
    with pytest.raises(RobotError, match="stood still"):
        await within(_never(), 1.0, "gripper", Clock(0.0), wall_clock=Clock(1.0), poll_s=0.001, backstop=5.0)


async def test_an_error_of_the_wait_is_raised_as_it_is() -> None:
    async def fail() -> None:
        raise RobotError("alarm 117")

    with pytest.raises(RobotError, match="alarm 117"):
        await within(fail(), 1.0, "x", Clock(0.0))
