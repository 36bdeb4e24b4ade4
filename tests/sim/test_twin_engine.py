"""TwinEngine as the simulated Dobot's MotionEngine: stepping, tracking, gripper, F/T, collisions."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.errors import CollisionDetectedError, ExecutionError, InvalidInputError
from services.sim.engine import EngineState, MotionEngine
from services.sim.twin import TwinEngine, create_twin_engine
from services.sim.twin import ground_truth as gt
from services.sim.twin.engine import OBJECT_DETECT_MAX_SPEED_M_S
from services.sim.twin.trial import TICK_S, ScriptedArm
from tests.sim.twin_helpers import HOME, top_down_tool, twin_settings

EMPTY = {"cubes": [], "rod": False, "obstacle": False}
ROD_AT = {"cubes": [], "obstacle": False, "pick_zone_min_m": (0.33, -0.03), "pick_zone_max_m": (0.57, 0.03)}


def quintic_move(
    engine: TwinEngine, q0: np.ndarray, q1: np.ndarray, duration_s: float, ticks: int | None = None
) -> list[EngineState]:
    """Follow a quintic joint move (optionally only its first ``ticks`` ticks)."""
    n = round(duration_s / TICK_S)
    dq, states = q1 - q0, []
    for k in range(1, (n if ticks is None else ticks) + 1):
        s = k / n
        p = 10 * s**3 - 15 * s**4 + 6 * s**5
        v = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration_s
        a = (60 * s - 180 * s**2 + 120 * s**3) / duration_s**2
        states.append(engine.step(TICK_S, q0 + dq * p, dq * v, dq * a))
    return states


def test_twin_loads_steps_and_is_a_motion_engine() -> None:
    engine = create_twin_engine(twin_settings(), seed=4)
    assert isinstance(engine, MotionEngine)
    assert np.allclose(engine.state().q, HOME)
    t0 = engine.time_s
    state = engine.step(TICK_S, HOME, np.zeros(6), np.zeros(6))
    assert engine.time_s == pytest.approx(t0 + TICK_S)
    assert state.q.shape == (6,) and state.collision is None
    # an uneven dt is carried over, not lost: 10 × 5 ms = 50 ms of sim time
    for _ in range(10):
        engine.step(0.005, HOME, np.zeros(6), np.zeros(6))
    assert engine.time_s == pytest.approx(t0 + TICK_S + 0.05, abs=engine.model.opt.timestep)
    # objects rest on the table
    for name in engine.world.object_body:
        assert gt.object_velocity(engine, name)[0] < 0.01


def test_measured_joints_track_the_reference_and_converge() -> None:
    engine = create_twin_engine(twin_settings(EMPTY), seed=0)
    target = np.deg2rad([20.0, -30.0, -120.0, 60.0, 90.0, -40.0])
    states = quintic_move(engine, HOME, target, 1.5)
    refs = [
        HOME + (target - HOME) * (10 * s**3 - 15 * s**4 + 6 * s**5)
        for s in np.arange(1, len(states) + 1) / len(states)
    ]
    errors = np.array([np.max(np.abs(st.q - r)) for st, r in zip(states, refs, strict=True)])
    assert errors.max() > 1e-5  # measured, not commanded: physics lags a little
    assert errors.max() < np.deg2rad(1.0)
    for _ in range(60):
        state = engine.step(TICK_S, target, np.zeros(6), np.zeros(6))
    assert np.max(np.abs(state.q - target)) < np.deg2rad(0.05)
    assert np.max(np.abs(state.qd)) < 0.01
    assert np.any(np.abs(state.effort) > 1.0)  # the joints carry the arm's weight


def test_gripper_follows_digital_outputs_and_reports_object_di() -> None:
    settings = twin_settings(ROD_AT, gripper={"object_di": 3})
    engine = create_twin_engine(settings, seed=0)
    arm = ScriptedArm(engine)
    stroke = settings.gripper.stroke_m
    assert engine.gripper_opening_m == pytest.approx(stroke, abs=1e-3)
    rod = gt.object_pose(engine, "rod")
    yaw = np.arctan2(rod[1, 2], rod[0, 2])
    above = top_down_tool(*rod[:2, 3], 0.10, yaw)
    arm.move_joints(arm.path_branch([above]), 1.5)
    arm.set_gripper(True, wait_s=0.6)  # closes in the air: fully shut, nothing held
    assert engine.gripper_closed and engine.gripper_opening_m < 1e-3
    assert arm.last.digital_inputs & (1 << 2) == 0
    arm.set_gripper(False, wait_s=0.6)
    assert engine.gripper_opening_m == pytest.approx(stroke, abs=1e-3)
    arm.move_linear(top_down_tool(*rod[:2, 3], rod[2, 3] + 0.001, yaw), 1.0)
    arm.set_gripper(True, wait_s=0.6)  # closes on the rod: stops at its diameter
    assert engine.gripper_opening_m == pytest.approx(settings.sim.twin.scene.rod_diameter_m, abs=1e-3)
    assert arm.last.digital_inputs & (1 << 2)
    arm.set_gripper(False, wait_s=0.6)
    assert arm.last.digital_inputs & (1 << 2) == 0
    # closed again, and lifted as soon as the signal comes (as the cycle does): the pads are still
    # settling on the rod, the fingers jitter, and the signal holds throughout the lift
    arm.set_gripper(True, wait_s=0.0)
    for _ in range(100):
        if arm.last.digital_inputs & (1 << 2):
            break
        arm.wait(0.008)
    # a brisk lift: the pads settle on the rod (the fingers jitter) and the signal holds throughout,
    # as a gripper's object-detected output does
    finger_speed: list[float] = []
    signal: list[int] = []

    def watch(state) -> bool:  # type: ignore[no-untyped-def]
        finger_speed.append(float(abs(engine.data.qvel[engine.world.finger_dof].sum())))
        signal.append(state.digital_inputs & (1 << 2))
        return False

    arm.move_linear(top_down_tool(*rod[:2, 3], rod[2, 3] + 0.15, yaw), 0.4, stop=watch)
    assert max(finger_speed) > OBJECT_DETECT_MAX_SPEED_M_S  # jittered: read instant by instant it would drop
    assert all(signal), f"object signal dropped at {signal.count(0)} of {len(signal)} ticks"
    assert gt.object_pose(engine, "rod")[2, 3] > rod[2, 3] + 0.1  # really lifted, really held
    arm.set_gripper(False, wait_s=0.6)
    assert arm.last.digital_inputs & (1 << 2) == 0


def test_digital_output_wiring_variants() -> None:
    engine = create_twin_engine(twin_settings(EMPTY), seed=0)
    engine.set_digital_outputs(0b01)
    assert engine.gripper_closed
    engine.set_digital_outputs(0b00)  # both off: a double-solenoid valve keeps its state
    assert engine.gripper_closed
    engine.set_digital_outputs(0b10)
    assert not engine.gripper_closed
    single = create_twin_engine(twin_settings(EMPTY, gripper={"open_do": None, "close_do": 4}), seed=0)
    single.set_digital_outputs(1 << 3)
    assert single.gripper_closed
    single.set_digital_outputs(0)
    assert not single.gripper_closed
    tool = create_twin_engine(twin_settings(EMPTY, gripper={"tool_outputs": True}), seed=0)
    tool.set_digital_outputs(0b01)  # cabinet DO1 is not the gripper
    assert not tool.gripper_closed
    tool.set_digital_outputs(1 << 32)  # ToolDO1
    assert tool.gripper_closed


def test_wrist_force_reads_zero_free_and_the_rod_weight_when_holding() -> None:
    settings = twin_settings(ROD_AT)
    engine = create_twin_engine(settings, seed=0)
    arm = ScriptedArm(engine)
    rod = gt.object_pose(engine, "rod")
    yaw = np.arctan2(rod[1, 2], rod[0, 2])
    arm.move_joints(arm.path_branch([top_down_tool(*rod[:2, 3], 0.10, yaw)]), 1.5)
    arm.wait(0.3)
    assert np.max(np.abs(arm.last.tcp_force[:3])) < 0.05  # tared: the gripper's own weight removed
    arm.move_linear(top_down_tool(*rod[:2, 3], rod[2, 3] + 0.001, yaw), 1.0)
    arm.set_gripper(True, wait_s=0.6)
    arm.move_linear(top_down_tool(*rod[:2, 3], 0.15, yaw), 1.0)
    arm.wait(0.3)
    weight = settings.sim.twin.scene.rod_mass_kg * 9.81
    assert arm.last.tcp_force[2] == pytest.approx(-weight, abs=0.05)


def test_driving_into_the_table_reports_a_collision_and_hold_relieves_it() -> None:
    engine = create_twin_engine(twin_settings(EMPTY), seed=0)
    arm = ScriptedArm(engine)
    arm.move_joints(arm.path_branch([top_down_tool(0.45, 0.0, 0.10)]), 1.5)
    assert engine.state().collision is None
    q_below = arm.ik(top_down_tool(0.45, 0.0, -0.06), arm.q)
    with pytest.raises(CollisionDetectedError, match="table"):
        arm.move_joints(q_below, 1.0)  # ScriptedArm calls engine.hold() on the collision
    text = engine.state().collision
    assert text is not None and "table" in text and " N" in text
    stale = arm.q.copy()  # the reference the arm was following when it hit
    q_hit = engine.state().q.copy()
    for _ in range(40):  # a controller that keeps sending the stale reference must not push on
        state = engine.step(TICK_S, stale, np.zeros(6), np.zeros(6))
    assert state.collision is None
    assert np.max(np.abs(state.q - q_hit)) < np.deg2rad(0.5)
    q_up = arm.ik(top_down_tool(0.45, 0.0, 0.10), q_hit)
    quintic_move(engine, state.q, q_up, 0.8)  # a new reference moves it again
    state = engine.settle(0.2)
    assert np.max(np.abs(state.q - q_up)) < np.deg2rad(0.1)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((0.0, HOME, np.zeros(6), np.zeros(6)), "dt"),
        ((float("nan"), HOME, np.zeros(6), np.zeros(6)), "dt"),
        ((TICK_S, HOME[:5], np.zeros(6), np.zeros(6)), "q_ref"),
        ((TICK_S, [np.nan] * 6, np.zeros(6), np.zeros(6)), "q_ref"),
        ((TICK_S, HOME, np.full(6, np.inf), np.zeros(6)), "qd_ref"),
        ((TICK_S, HOME, np.zeros(6), "fast"), "qdd_ref"),
    ],
)
def test_bad_step_input_is_rejected(args: tuple, match: str) -> None:
    engine = create_twin_engine(twin_settings(EMPTY), seed=0)
    with pytest.raises(InvalidInputError, match=match):
        engine.step(*args)
    assert np.allclose(engine.state().q, HOME)  # nothing moved


def test_misuse_raises() -> None:
    engine = create_twin_engine(twin_settings(EMPTY), seed=0)
    with pytest.raises(InvalidInputError):
        engine.set_digital_outputs(-1)
    with pytest.raises(InvalidInputError):
        engine.reset(np.zeros(4))
    engine.close()
    with pytest.raises(ExecutionError, match="closed"):
        engine.step(TICK_S, HOME, np.zeros(6), np.zeros(6))
