"""Contact grasp of the rod in the twin (no weld, no attach) and the pick-and-stand success checks."""

from __future__ import annotations

import mujoco
import pytest

from services.common.errors import InvalidInputError
from services.sim.twin import create_twin_engine
from services.sim.twin import ground_truth as gt
from services.sim.twin.trial import ScriptedArm, rod_stand_poses, run_rod_stand_trial
from tests.sim.twin_helpers import twin_settings

ROD_ONLY = {"cubes": [], "obstacle": False}


def test_twin_has_no_weld_or_attachment() -> None:
    engine = create_twin_engine(twin_settings(), seed=0)
    m = engine.model
    assert all(m.eq_type[i] != mujoco.mjtEq.mjEQ_WELD for i in range(m.neq))
    assert all(m.eq_type[i] != mujoco.mjtEq.mjEQ_CONNECT for i in range(m.neq))
    rod_body = engine.world.object_body["rod"]
    assert m.body_parentid[rod_body] == 0  # a free body of the world, not a child of the gripper


def test_closed_gripper_holds_the_rod_through_lift_and_turn_and_opening_releases_it() -> None:
    settings = twin_settings(ROD_ONLY)
    engine = create_twin_engine(settings, seed=5)
    arm = ScriptedArm(engine)
    T_rod = gt.object_pose(engine, "rod")
    poses = rod_stand_poses(T_rod, lift_m=0.15)
    arm.move_joints(
        arm.path_branch([poses["pre_grasp"], poses["grasp"], poses["lift"], poses["turned"]]), 2.0
    )
    arm.move_linear(poses["grasp"], 1.0)
    arm.set_gripper(True, wait_s=0.6)
    T_ref = gt.T_tool_object(engine, "rod")
    assert gt.robot_touches(engine, "rod")
    arm.move_linear(poses["lift"], 1.5)
    lifted = gt.object_pose(engine, "rod")
    assert lifted[2, 3] > T_rod[2, 3] + 0.14  # it came up with the gripper
    assert gt.axis_tilt_deg(lifted) > 85.0  # still lying horizontally in the grasp
    arm.move_linear(poses["turned"], 2.0)
    arm.wait(0.3)
    turned = gt.object_pose(engine, "rod")
    assert gt.axis_tilt_deg(turned) < 3.0  # now upright in the air
    assert turned[2, 3] > 0.12
    slip_mm, slip_deg = gt.slip(T_ref, gt.T_tool_object(engine, "rod"))
    assert slip_mm < 5.0 and slip_deg < 2.0
    arm.set_gripper(False, wait_s=0.8)  # open in the air: the rod drops to the table
    engine.settle(1.0)
    dropped = gt.object_pose(engine, "rod")
    assert dropped[2, 3] < 0.11 and not gt.robot_touches(engine, "rod")


@pytest.mark.parametrize("seed", [2, 7])
def test_scripted_pick_and_stand_trial_stands_the_rod(seed: int) -> None:
    engine = create_twin_engine(twin_settings(ROD_ONLY), seed=seed)
    result = run_rod_stand_trial(engine)
    assert result.error is None
    assert result.success, result.stand
    assert result.stand is not None and result.stand.tilt_deg < 5.0 and result.stand.gripper_clear
    assert result.metrics.extra["touch_detected"] == 1.0  # touch-down felt by the wrist sensor
    assert result.metrics.tilt_before_place_deg is not None and result.metrics.tilt_before_place_deg < 3.0
    assert result.metrics.slip_mm < 5.0


def test_a_slippery_grasp_drops_the_rod() -> None:
    """Contact physics, not an attachment: with slippery pads the same grasp cannot lift the rod."""
    settings = twin_settings(ROD_ONLY, physics={"pad_friction": 0.02})
    engine = create_twin_engine(settings, seed=5)
    arm = ScriptedArm(engine)
    T_rod = gt.object_pose(engine, "rod")
    poses = rod_stand_poses(T_rod, lift_m=0.15)
    arm.move_joints(arm.path_branch([poses["pre_grasp"], poses["grasp"], poses["lift"]]), 2.0)
    arm.move_linear(poses["grasp"], 1.0)
    arm.set_gripper(True, wait_s=0.6)
    arm.move_linear(poses["lift"], 1.5)
    engine.settle(0.5)
    assert gt.object_pose(engine, "rod")[2, 3] < T_rod[2, 3] + 0.02


def test_rod_lying_on_the_table_is_not_standing() -> None:
    engine = create_twin_engine(twin_settings(ROD_ONLY), seed=1)
    result = gt.evaluate_rod_standing(engine, settle_s=0.2)
    assert not result.success
    assert result.tilt_deg == pytest.approx(90.0, abs=0.5)
    assert any("tilted" in r for r in result.reasons)


def test_cube_in_drop_zone_check() -> None:
    settings = twin_settings({"rod": False, "cubes": ["red", "blue"], "obstacle": False})
    engine = create_twin_engine(settings, seed=3)
    assert not gt.check_cube_in_zone(engine, "red").success  # spawned in the pick zone
    # evaluation-only teleport: put the red cube 1 cm from its zone centre and let it settle
    zone = settings.sim.twin.scene.drop_zones_m["red"]
    adr = engine.world.object_qpos["cube_red"]
    with engine.lock:
        engine.data.qpos[adr : adr + 3] = [zone[0] + 0.01, zone[1], 0.026]
        engine.data.qpos[adr + 3 : adr + 7] = [1.0, 0.0, 0.0, 0.0]
    engine.settle(0.5)
    ok = gt.check_cube_in_zone(engine, "red")
    assert ok.success and ok.distance_m == pytest.approx(0.01, abs=0.002)
    far = gt.check_cube_in_zone(engine, "red", tolerance_m=0.005)
    assert not far.success and "mm from the zone" in far.reasons[0]
    with pytest.raises(InvalidInputError, match="no drop zone"):
        gt.check_cube_in_zone(engine, "purple")
