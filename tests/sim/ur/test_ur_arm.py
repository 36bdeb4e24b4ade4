"""The simulated UR arm's servoj (pure, controller time): URScript's servoj blocks for its ``t``, so a
target given while one still runs is taken up when that one's time is over, on schedule."""

from __future__ import annotations

import numpy as np
import pytest

from services.kinematics.robot_models import get_robot
from services.sim.ur.arm import ArmMotion, MotionKind, SafetyViolation

DT = 0.002
T = 0.03  # 15 control cycles per target


def _arm() -> ArmMotion:
    return ArmMotion(get_robot("ur5e"), np.zeros(6))


def _run(arm: ArmMotion, seconds: float) -> None:
    for _ in range(round(seconds / DT)):
        arm.step(DT)


def test_a_servoj_target_given_while_one_runs_follows_it_at_the_planned_speed() -> None:
    arm = _arm()
    step = np.full(6, 0.03)  # 1 rad/s over t: well within every joint's limit
    arm.servoj(step, T)
    _run(arm, T / 3)
    arm.servoj(2 * step, T)  # early: the first still has 2/3 of its t to run
    _run(arm, 2 * T / 3)
    assert np.allclose(arm.ref.q, step)  # the first target reached on its own schedule ...
    _run(arm, T)
    assert np.allclose(arm.ref.q, 2 * step)  # ... and the second one t later, not sooner
    assert arm.kind is MotionKind.SERVOJ  # servoj holds its last target until stopped


def test_a_servoj_target_too_far_for_its_t_is_a_safety_violation_when_taken_up() -> None:
    arm = _arm()
    arm.servoj(np.full(6, 0.03), T)
    _run(arm, DT)
    arm.servoj(np.full(6, 0.03 + 0.2), T)  # 0.2 rad in 30 ms: 6.7 rad/s
    with pytest.raises(SafetyViolation, match="joint speed limit"):
        _run(arm, T)


def test_a_stop_drops_a_servoj_target_not_yet_taken_up() -> None:
    arm = _arm()
    arm.servoj(np.full(6, 0.03), T)
    _run(arm, DT)
    arm.servoj(np.full(6, 0.06), T)
    arm.stop(4.0)
    _run(arm, 0.5)  # braked from 1 rad/s at 4 rad/s²: at rest within 0.25 s
    q_rest = arm.ref.q.copy()
    _run(arm, 0.5)
    assert arm.kind is MotionKind.IDLE and np.array_equal(arm.ref.q, q_rest)
