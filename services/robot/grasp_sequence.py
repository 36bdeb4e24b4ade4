"""The grasp sequence of LLD §13.2 (ExecuteGrasp), on the driver's checked motions."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from services.common.errors import InvalidInputError
from services.kinematics import analytic
from services.kinematics.cartesian import straight_line_joint_path
from services.kinematics.interpolation import min_jerk_keypose_trajectory
from services.kinematics.trajectory import JointLimits, JointTrajectory
from services.robot.gripper import GripperState

if TYPE_CHECKING:
    from services.robot.driver import RobotDriver


async def execute_grasp(
    driver: RobotDriver,
    T_base_tool: np.ndarray,
    approach_m: float = 0.10,
    lift_m: float = 0.10,
    speed_scale: float = 0.3,
) -> GripperState:
    """Open, move above the grasp along the tool axis, descend in a straight line, close, lift.

    Every segment is checked like any trajectory (joints, speed, workspace) before it is sent;
    there is no obstacle avoidance here — the task service plans collision-free picks."""
    if driver.limits.T_flange_tool is None:
        raise InvalidInputError("ExecuteGrasp needs the gripper's tool offset (gripper.tcp_offset_m)")
    for name, v in (("approach_distance", approach_m), ("lift_distance", lift_m)):
        if not (np.isfinite(v) and 0.0 <= v <= 0.5):
            raise InvalidInputError(f"{name} must be within 0..0.5 m, got {v}")
    if not (np.isfinite(speed_scale) and 0.0 < speed_scale <= 1.0):
        raise InvalidInputError(f"speed_scale must be within (0, 1], got {speed_scale}")
    T_grasp = np.asarray(T_base_tool, dtype=float)
    T_above = T_grasp.copy()
    T_above[:3, 3] -= approach_m * T_grasp[:3, 2]  # back along the approach (tool z)
    T_lift = T_grasp.copy()
    T_lift[2, 3] += lift_m
    limits = JointLimits.from_spec(driver.spec, speed_scale, speed_scale)
    q_now = driver.joint_positions()
    T_ft = driver.limits.T_flange_tool
    q_above = analytic.solve_nearest(driver.spec, T_above @ np.linalg.inv(T_ft), q_now)

    def timed(path: np.ndarray) -> JointTrajectory:
        return min_jerk_keypose_trajectory(
            path, 0.05, 0.0, joint_names=driver.spec.joint_names, limits=limits, wrap=False
        )

    # the whole motion is solved and checked before anything moves
    down = straight_line_joint_path(driver.spec, T_above, T_grasp, q_above, T_flange_tool=T_ft)
    up = straight_line_joint_path(driver.spec, T_grasp, T_lift, down[-1], T_flange_tool=T_ft)
    for name, path in (("approach", np.vstack([q_now, q_above])), ("descent", down), ("lift", up)):
        driver.limits.check_all(path, f"grasp {name}")
    await driver.set_gripper(False)
    await driver.execute_trajectory(timed(np.vstack([q_now, q_above])))
    await driver.execute_trajectory(timed(_thin(down)))
    state = await driver.set_gripper(True)
    await driver.execute_trajectory(timed(_thin(up)))
    return state


def _thin(path: np.ndarray, knots: int = 20) -> np.ndarray:
    """At most ``knots`` points of a dense path, always keeping its last point."""
    if len(path) <= knots:
        return path
    idx = np.unique(np.append(np.linspace(0, len(path) - 1, knots).round().astype(int), len(path) - 1))
    return path[idx]
