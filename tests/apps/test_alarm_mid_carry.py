"""A robot alarm while the rod is carried (issue 13): the twin's controller raises it in the middle of
the REORIENT motion; the task clears it and resumes from REORIENT with the rod still in the gripper
(never DETECT again), and the rod ends standing. Judged by the controller's alarm, the states the
task went through and the twin's ground truth."""

from __future__ import annotations

import asyncio

import pytest

from services.apps.cell import Cell
from services.common.modes import TaskKind
from services.dobot.codes import Alarm
from services.sim.twin import ground_truth as gt
from services.task.states import CycleState
from tests.apps.conftest import cell_settings

pytestmark = [pytest.mark.integration, pytest.mark.slow]

ALARM_AFTER_S = 0.3  # of controller time into the REORIENT motion


async def test_an_alarm_mid_carry_resumes_from_reorient_with_the_rod_and_stands_it(tmp_path):
    s = cell_settings(
        tmp_path,
        # safety nets for a loaded machine: a link hiccup after the alarm is not what is tested here
        robot={"request_timeout_s": 10.0, "feedback_timeout_s": 5.0},
        task={"alarm_recoveries": 4},
    )
    async with Cell(s, seed=3) as cell:
        assert cell.sim is not None
        sim, ctrl = cell.sim, cell.sim.controller
        runner = cell.task.runner
        orch = runner.orchestrator
        states: list[tuple[CycleState, str]] = []
        raised: list[bool] = []
        injector: list[asyncio.Task[None]] = []

        async def alarm_mid_motion() -> None:
            await cell.settle(ALARM_AFTER_S)  # on the controller's clock
            with sim.lock:
                raised.append(ctrl.motion is not None or bool(ctrl.queue))  # the arm was moving
                ctrl.raise_alarm(Alarm.COLLISION, "injected while carrying the rod")

        def on_state(state: CycleState, message: str) -> None:
            states.append((state, message))
            runner._on_state(state, message)
            if state is CycleState.REORIENT and not injector:
                injector.append(asyncio.get_running_loop().create_task(alarm_mid_motion()))

        orch._on_state = on_state
        outcome = await runner.run_cycle(TaskKind.STAND_ROD)
        await injector[0]
        assert raised == [True], "the alarm was not raised while the arm moved"
        assert outcome.success, outcome.failure_reason
        assert outcome.attempts >= 2
        names = [st for st, _ in states]
        i = names.index(CycleState.REORIENT)
        after = names[i:]
        assert CycleState.DETECT not in after and CycleState.PLAN not in after  # never looked again
        resumed = [m for _, m in states[i:] if m.startswith("resuming at")]
        assert resumed and "after ControllerError" in resumed[0], states[i:]
        assert resumed[0].split()[2] in ("REORIENT", "CARRY", "PLACE_ABOVE", "PLACE"), resumed  # carrying
        await cell.settle(1.0)
        standing = gt.check_rod_standing(cell.engine)
        assert standing.success, standing.reasons
