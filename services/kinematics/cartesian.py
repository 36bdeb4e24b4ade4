"""Straight-line Cartesian paths: pose interpolation, IK at every step, jump detection.

The tool moves along the straight line between poses (position linear, orientation
by slerp) in steps of at most ``step_m`` / ``step_rad``; IK at each step is seeded
with the previous step's joints (the closest branch). A step whose joints change by
more than ``jump_threshold_rad`` means the arm would flip branch or pass a
singularity between the samples, so the whole path is refused (IKFailureError
naming where), rather than executed with a jump — the same guard MoveIt's
``computeCartesianPath`` has as ``jump_threshold``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation, Slerp

from services.common.errors import IKFailureError, InvalidInputError
from services.kinematics import analytic
from services.kinematics.poses import check_pose, pose_text
from services.kinematics.robot_models import RobotSpec
from services.kinematics.trajectory import Array, joint_vector

if TYPE_CHECKING:  # pinocchio is imported only by callers that use Kinematics
    from services.kinematics.model import Kinematics

DEFAULT_STEP_M = 0.005
DEFAULT_STEP_RAD = math.radians(2.0)
DEFAULT_JUMP_RAD = math.radians(10.0)


def interpolate_poses(
    T_start: Array, T_goal: Array, step_m: float = DEFAULT_STEP_M, step_rad: float = DEFAULT_STEP_RAD
) -> Array:
    """Poses (n, 4, 4) along the straight line, endpoints included, evenly spaced (lerp + slerp)."""
    if not (math.isfinite(step_m) and step_m > 0 and math.isfinite(step_rad) and step_rad > 0):
        raise InvalidInputError(f"Cartesian steps must be positive, got {step_m} m, {step_rad} rad")
    dist = float(np.linalg.norm(T_goal[:3, 3] - T_start[:3, 3]))
    rots = Rotation.from_matrix(np.stack([T_start[:3, :3], T_goal[:3, :3]]))
    angle = float((rots[0].inv() * rots[1]).magnitude())
    n = max(2, math.ceil(max(dist / step_m, angle / step_rad) - 1e-9) + 1)
    s = np.linspace(0.0, 1.0, n)
    out = np.tile(np.eye(4), (n, 1, 1))
    out[:, :3, 3] = T_start[:3, 3] + s[:, None] * (T_goal[:3, 3] - T_start[:3, 3])
    out[:, :3, :3] = Slerp([0.0, 1.0], rots)(s).as_matrix()
    out[0], out[-1] = T_start, T_goal
    return out


def cartesian_path(
    kin: Kinematics,
    q_start: ArrayLike,
    targets: Sequence[ArrayLike],
    *,
    step_m: float = 0.005,
    step_rad: float = math.radians(2.0),
    jump_threshold_rad: float = math.radians(10.0),
) -> Array:
    """Joint path (N, dof) that moves the tool in straight lines from FK(q_start) through ``targets``.

    Raises IKFailureError when a step has no IK solution within limits (naming the
    pose and how far along the path it is) or when the joints jump.
    """
    q0 = kin.limits.check_positions(q_start, "start")
    if not (math.isfinite(jump_threshold_rad) and jump_threshold_rad > 0):
        raise InvalidInputError(f"jump threshold must be positive, got {jump_threshold_rad}")
    poses = [check_pose(T, f"Cartesian target {k}") for k, T in enumerate(targets)]
    if not poses:
        raise InvalidInputError("a Cartesian path needs at least one target pose")
    analytic = kin.has_analytic_ik()
    rows = [q0]
    q_prev = q0
    T_prev = kin.fk(q0)
    for seg, T_goal in enumerate(poses):
        steps = interpolate_poses(T_prev, T_goal, step_m, step_rad)
        for k, T in enumerate(steps[1:], start=1):
            q = _step_ik(kin, T, q_prev, analytic)
            if q is None:
                raise IKFailureError(
                    f"{kin.spec.name}: Cartesian segment {seg} has no IK solution within joint limits at "
                    f"{k}/{len(steps) - 1} of the way, tool at {pose_text(T)}"
                )
            jump = float(np.max(np.abs(q - q_prev)))
            if jump > jump_threshold_rad:
                j = int(np.argmax(np.abs(q - q_prev)))
                raise IKFailureError(
                    f"{kin.spec.name}: Cartesian segment {seg} would make joint {j + 1} jump "
                    f"{math.degrees(jump):.1f}° (limit {math.degrees(jump_threshold_rad):.1f}°) at "
                    f"{k}/{len(steps) - 1} of the way, tool at {pose_text(T)} (singularity or branch change)"
                )
            rows.append(q)
            q_prev = q
        T_prev = T_goal
    return np.array(rows)


def _step_ik(kin: Kinematics, T: Array, q_prev: Array, analytic: bool) -> Array | None:
    if analytic:
        sols = kin.ik_analytic(T, q_prev)
        if sols.shape[0] == 0:
            return None
        # nearest in the Euclidean sense: the same branch as the previous step
        return sols[int(np.argmin(np.linalg.norm(sols - q_prev, axis=1)))]
    try:
        return kin.ik_numeric(T, q_prev, restarts=0, max_iter=40)
    except IKFailureError:
        return None


def straight_line_joint_path(
    spec: RobotSpec,
    T_start: ArrayLike,
    T_goal: ArrayLike,
    q_seed: ArrayLike,
    *,
    step_m: float = DEFAULT_STEP_M,
    step_rad: float = DEFAULT_STEP_RAD,
    max_joint_step_rad: float = DEFAULT_JUMP_RAD,
    T_flange_tool: ArrayLike | None = None,
) -> Array:
    """Joint configurations along a straight tool line, each the IK branch nearest the previous.

    Closed-form IK only (no pinocchio), for the simulated controller's MovL. The first
    row is the solution for ``T_start`` nearest ``q_seed``. Raises IKFailureError when a
    step has no solution within limits, or when the joints would jump by more than
    ``max_joint_step_rad`` between neighbouring steps (the message then says "jump": a
    singularity or a branch change — the path is refused, not silently flipped).
    """
    prev = joint_vector(q_seed, spec.dof, "seed joints")
    Ta = check_pose(T_start, "line start pose")
    Tb = check_pose(T_goal, "line goal pose")
    if not (math.isfinite(max_joint_step_rad) and max_joint_step_rad > 0):
        raise InvalidInputError(f"jump threshold must be positive, got {max_joint_step_rad}")
    poses = interpolate_poses(Ta, Tb, step_m, step_rad)
    if T_flange_tool is not None:
        poses = poses @ np.linalg.inv(check_pose(T_flange_tool, "T_flange_tool"))
    path = np.empty((len(poses), spec.dof))
    for i, T in enumerate(poses):
        cands = analytic.solutions_within_limits(spec, T, prev)
        if cands.shape[0] == 0:
            raise IKFailureError(
                f"{spec.name}: the straight line leaves the reachable workspace at step {i}/{len(poses) - 1} "
                f"(flange at {pose_text(T)})"
            )
        jumps = np.max(np.abs(cands - prev), axis=1)
        k = int(np.argmin(jumps))
        if i > 0 and jumps[k] > max_joint_step_rad:
            raise IKFailureError(
                f"{spec.name}: the straight line needs a joint jump of {math.degrees(jumps[k]):.1f}° at step "
                f"{i}/{len(poses) - 1}, flange at {pose_text(T)} (singular or branch change)"
            )
        prev = cands[k]
        path[i] = prev
    return path
