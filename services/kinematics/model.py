"""Kinematics on the URDF models with pinocchio: FK, Jacobians, analytic and numerical IK.

- :func:`load_arm` builds (and caches) the pinocchio model and collision geometry of an
  arm with a given tool from :mod:`services.kinematics.urdf`.
- :class:`Kinematics` holds one pinocchio ``Data`` (not thread-safe: one per thread or
  request) and offers FK for any frame, the tool Jacobian, manipulability, the
  closed-form IK for the UR-structure arms (all solutions within limits, exact on this
  URDF: :mod:`services.kinematics.analytic` solves the same joint chain, with the tool
  folded in, in closed form — no table to refine), a damped-least-squares / Levenberg–Marquardt numerical IK for any URDF and tool
  frame with random restarts and unwrapping to the seed, and :meth:`Kinematics.solve_ik`,
  which picks the solution nearest the seed away from singularities.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import lapack

from services.common.errors import ConfigurationError, IKFailureError, InvalidInputError
from services.common.frames import invert_transform, rotation_angle_rad
from services.kinematics import analytic
from services.kinematics.analytic import KinematicModel
from services.kinematics.poses import check_pose, pose_text
from services.kinematics.robot_models import RobotSpec, get_robot
from services.kinematics.tool import ToolGeometry
from services.kinematics.trajectory import Array, JointLimits, joint_vector
from services.kinematics.urdf import flange_link, robot_urdf

TOOL_FRAME = "tool_tip"
# Below this Yoshikawa manipulability an IK solution counts as near-singular (UR-size arms
# reach ~0.01-0.1 in the middle of the workspace; see tests and the benchmark).
DEFAULT_MIN_MANIPULABILITY = 1e-3
# Levenberg–Marquardt: damping λ = _LM_DAMPING·|e|² + _LM_DAMPING_FLOOR (Sugihara 2011:
# Gauss–Newton near the solution, gradient-like far from it). The floor is tiny so that targets
# next to a singularity (σ_min ~ 1e-5) still converge; tuned on random reachable poses from a
# cold seed (0.01 with 1 rad steps: 9 iterations median where 0.1 with 0.6 rad steps took 11).
_LM_DAMPING = 0.01
_LM_DAMPING_FLOOR = 1e-9
_STALL_STEPS = 6
_TWO_PI = 2 * math.pi


@dataclass(frozen=True)
class ArmModel:
    """An arm with its tool: pinocchio kinematic and collision models (shared, read-only)."""

    spec: RobotSpec
    tool: ToolGeometry
    urdf: str
    model: pin.Model
    collision_model: pin.GeometryModel
    tool_frame: int
    flange_frame: int
    T_flange_tool: Array

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.spec.joint_names

    def limits(self, velocity_scale: float = 1.0, acceleration_scale: float = 1.0) -> JointLimits:
        return JointLimits.from_spec(self.spec, velocity_scale, acceleration_scale)


@functools.lru_cache(maxsize=16)
def _load(name: str, tool: ToolGeometry) -> ArmModel:
    spec = get_robot(name)
    urdf = robot_urdf(spec, tool)
    model = pin.buildModelFromXML(urdf)
    names = tuple(model.names[1:])
    if names != spec.joint_names:
        raise ConfigurationError(f"{name} URDF joints {names} differ from the model's {spec.joint_names}")
    geom = pin.buildGeomFromUrdfString(model, urdf, pin.COLLISION)
    # URDF has no capsule: the link pieces are written as cylinders and checked as capsules
    for obj in geom.geometryObjects:
        if isinstance(obj.geometry, coal.Cylinder):
            obj.geometry = coal.Capsule(obj.geometry.radius, 2.0 * obj.geometry.halfLength)
    tool_frame = model.getFrameId(TOOL_FRAME)
    flange_frame = model.getFrameId(flange_link(spec))
    if tool_frame >= model.nframes or flange_frame >= model.nframes:
        raise ConfigurationError(f"{name} URDF lacks the {TOOL_FRAME!r} or flange frame")
    return ArmModel(spec, tool, urdf, model, geom, tool_frame, flange_frame, tool.T_flange_tool())


def load_arm(name: str | RobotSpec = "nova5", tool: ToolGeometry | None = None) -> ArmModel:
    """The arm model for ``name`` (nova5, ur5e, ur3) with ``tool`` (default gripper)."""
    key = name.name if isinstance(name, RobotSpec) else name
    return _load(key, tool or ToolGeometry())


def arm_from_urdf(
    urdf: str,
    tool_frame: str,
    *,
    name: str = "custom",
    acceleration_per_velocity: float = 3.0,
    default_velocity: float = 1.0,
) -> ArmModel:
    """An arm from any serial URDF (revolute/prismatic joints) with ``tool_frame`` as the TCP.

    For the numerical IK, FK and collision checks (no closed-form IK). Limits come from the
    URDF; a joint without a velocity limit gets ``default_velocity`` rad/s; accelerations are
    ``acceleration_per_velocity`` × velocity per second, jerks 10 × acceleration per second.
    """
    try:
        model = pin.buildModelFromXML(urdf)
    except Exception as exc:  # pinocchio raises plain ValueError/RuntimeError on bad XML
        raise ConfigurationError(f"cannot read the URDF: {exc}") from exc
    if model.nq != model.nv or model.nq == 0:
        raise ConfigurationError("only URDFs with revolute or prismatic (not continuous or floating) joints")
    fid = model.getFrameId(tool_frame)
    if fid >= model.nframes:
        raise ConfigurationError(f"the URDF has no frame {tool_frame!r}")
    lower = np.asarray(model.lowerPositionLimit, dtype=float).copy()
    upper = np.asarray(model.upperPositionLimit, dtype=float).copy()
    vel = np.asarray(model.velocityLimit, dtype=float).copy()
    vel = np.where(vel > 0, vel, default_velocity)
    n = model.nq
    spec = RobotSpec(
        name=name,
        joint_names=tuple(model.names[1:]),
        d=np.zeros(n),
        a=np.zeros(n),
        alpha=np.zeros(n),
        theta_offset=np.zeros(n),
        lower=lower,
        upper=upper,
        max_velocity=vel,
        max_acceleration=vel * acceleration_per_velocity,
        max_jerk=vel * acceleration_per_velocity * 10.0,
        reach_m=0.0,
    )
    geom = pin.buildGeomFromUrdfString(model, urdf, pin.COLLISION)
    for obj in geom.geometryObjects:
        if isinstance(obj.geometry, coal.Cylinder):
            obj.geometry = coal.Capsule(obj.geometry.radius, 2.0 * obj.geometry.halfLength)
    return ArmModel(spec, ToolGeometry(), urdf, model, geom, fid, fid, np.eye(4))


@dataclass(frozen=True)
class IKSolution:
    q: Array
    manipulability: float
    method: str  # "analytic" or "numeric"
    position_error_m: float
    rotation_error_rad: float


class Kinematics:
    """FK/IK for one arm + tool. Holds a pinocchio Data: use one instance per thread."""

    def __init__(self, arm: ArmModel):
        self.arm = arm
        self.spec = arm.spec
        self.model = arm.model
        self.data = arm.model.createData()
        self.limits = arm.limits()
        self._T_tool_flange = invert_transform(arm.T_flange_tool)
        # random restarts sample each joint within its limits, at most one turn either side
        self._sample_lo = np.maximum(self.limits.lower, -math.pi)
        self._sample_hi = np.minimum(self.limits.upper, math.pi)
        self._continuous = self.limits.continuous()
        self._continuous_idx = tuple(int(i) for i in np.flatnonzero(self._continuous))
        self._lower = self.limits.lower.tolist()
        self._upper = self.limits.upper.tolist()
        self._ik_chain = self._closed_form_chain()

    def _closed_form_chain(self) -> analytic.Chain | None:
        """The URDF's joint chain ending at the tool tip, when the closed form applies to it and it
        is this arm's URDF (checked against pinocchio: an arm read with ``arm_from_urdf`` under one
        of our names but from another file gets the numerical IK only)."""
        try:
            ch = analytic.chain(self.spec, KinematicModel.URDF).with_tool(self.arm.T_flange_tool)
        except ConfigurationError:
            return None  # not one of our arms
        if ch.closed_form is None:
            return None
        probe = np.array([[0.0] * 6, [0.3, -1.1, 1.7, -0.4, 0.9, 2.2]])
        same = all(np.abs(analytic.chain_fk(ch, q) - self.fk(q)).max() < 1e-12 for q in probe)
        return ch if same else None

    @property
    def dof(self) -> int:
        return self.spec.dof

    # --- forward ------------------------------------------------------------------------------
    def fk(self, q: ArrayLike, frame: str = TOOL_FRAME) -> Array:
        """Pose (4x4) of a URDF frame (default the tool tip) in the base frame."""
        qv = joint_vector(q, self.dof, "joint positions")
        fid = self.arm.tool_frame if frame == TOOL_FRAME else self._frame_id(frame)
        pin.forwardKinematics(self.model, self.data, qv)
        return pin.updateFramePlacement(self.model, self.data, fid).homogeneous.copy()

    def _frame_id(self, frame: str) -> int:
        fid = self.model.getFrameId(frame)
        if fid >= self.model.nframes:
            raise InvalidInputError(f"{self.spec.name} has no frame {frame!r}")
        return int(fid)

    def tool_to_flange(self, T_base_tool: Array) -> Array:
        return T_base_tool @ self._T_tool_flange

    def jacobian(self, q: ArrayLike) -> Array:
        """Geometric Jacobian (6 x dof) of the tool tip, expressed in base-aligned axes."""
        qv = joint_vector(q, self.dof)
        return pin.computeFrameJacobian(
            self.model, self.data, qv, self.arm.tool_frame, pin.LOCAL_WORLD_ALIGNED
        )

    def manipulability(self, q: ArrayLike) -> float:
        """Yoshikawa's measure sqrt(det(J Jᵀ)) of the flange Jacobian (0 at a singularity).

        The flange is used so that the value does not depend on the tool offset. Computed as the
        product of J's singular values, which stays accurate near a singularity where det(J Jᵀ) is
        rounding noise.
        """
        qv = joint_vector(q, self.dof)
        J = pin.computeFrameJacobian(
            self.model, self.data, qv, self.arm.flange_frame, pin.LOCAL_WORLD_ALIGNED
        )
        return float(np.prod(np.linalg.svd(J, compute_uv=False)))

    def pose_error(self, q: ArrayLike, T_base_tool: Array) -> tuple[float, float]:
        """(position error m, rotation error rad) of the tool at q against a target."""
        T = self.fk(q)
        angle = rotation_angle_rad(T[:3, :3], T_base_tool[:3, :3])
        return float(np.linalg.norm(T[:3, 3] - T_base_tool[:3, 3])), angle

    # --- inverse ------------------------------------------------------------------------------
    def has_analytic_ik(self) -> bool:
        return self._ik_chain is not None

    def ik_analytic(self, T_base_tool: Array, seed: ArrayLike | None = None) -> Array:
        """All closed-form solutions within joint limits, each on the turn nearest ``seed``,
        sorted by distance to it: (k, dof), k ≤ 8 (may be empty). Each reproduces the tool pose
        on this URDF to rounding (a pose a hair beyond the workspace boundary: within 1e-6)."""
        if self._ik_chain is None:
            raise ConfigurationError(f"{self.spec.name} has no closed-form IK")
        T = check_pose(T_base_tool)
        return analytic.solve_within_limits(
            self._ik_chain, T, self._seed_list(seed), self._lower, self._upper
        )

    def _seed_list(self, seed: ArrayLike | None) -> list[float] | None:
        """The seed as floats: fast acceptance of a finite float vector (the IK hot path), anything
        else through joint_vector for its message."""
        if seed is None:
            return None
        if isinstance(seed, np.ndarray) and seed.shape == (self.dof,) and seed.dtype == np.float64:
            values: list[float] = seed.tolist()
            if math.isfinite(sum(values)):
                return values
        return joint_vector(seed, self.dof, "seed").tolist()

    def ik_numeric(
        self,
        T_base_tool: Array,
        seed: ArrayLike,
        *,
        rng: np.random.Generator | None = None,
        restarts: int = 100,
        max_iter: int = 100,
        tol: float = 1e-6,
        max_step_rad: float = 1.0,
    ) -> Array:
        """Levenberg–Marquardt IK of the tool tip from ``seed``, then random restarts.

        Damping λ = 0.01·|e|² + 1e-9 (Sugihara's LM: Gauss–Newton near the solution,
        gradient-like far away); a run that stalls far from the target is abandoned for a
        random restart; steps are capped at ``max_step_rad`` per joint; joints are kept
        within their limits (wrapped on full-turn joints, clipped on the others). The result is
        unwrapped to the turn nearest the seed, so a ±360° joint never flips by a full
        revolution. IKFailureError (naming the pose) when no attempt converges to ``tol``
        (twist norm, m and rad).
        """
        T = check_pose(T_base_tool)
        q0 = joint_vector(seed, self.dof, "seed")
        target = pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
        lo, hi = self.limits.lower, self.limits.upper
        cont = self._continuous
        q = self._converge(np.clip(q0, lo, hi), target, tol, max_iter, max_step_rad, lo, hi, cont)
        if q is not None:
            return self._unwrap_to_seed(q, q0)
        if restarts:
            rng = rng if rng is not None else np.random.default_rng(0)  # made only when needed: 8 µs
            for _ in range(restarts):
                q = rng.uniform(self._sample_lo, self._sample_hi)
                q = self._converge(q, target, tol, max_iter, max_step_rad, lo, hi, cont)
                if q is not None:
                    return self._unwrap_to_seed(q, q0)
        raise IKFailureError(
            f"{self.spec.name}: numerical IK did not converge for the tool at {pose_text(T)} "
            f"(seed {np.round(q0, 4).tolist()} rad, {restarts} restarts)"
        )

    def _unwrap_to_seed(self, q: Array, seed: Array) -> Array:
        """Full-turn joints moved by whole turns to the value nearest the seed, within limits.

        Plain floats: for six joints this is several times faster than the numpy form (IK hot path).
        """
        out = q.tolist()
        for i in self._continuous_idx:
            qi = out[i] + _TWO_PI * round((seed[i] - out[i]) / _TWO_PI)
            if qi > self._upper[i]:
                qi -= _TWO_PI
            elif qi < self._lower[i]:
                qi += _TWO_PI
            if self._lower[i] <= qi <= self._upper[i]:
                out[i] = qi
        return np.array(out)

    def _converge(
        self,
        q: Array,
        target: pin.SE3,
        tol: float,
        max_iter: int,
        max_step: float,
        lo: Array,
        hi: Array,
        cont: NDArray[np.bool_],
    ) -> Array | None:
        """One LM run from q; None when it stalls far from the target or runs out of iterations."""
        model, data = self.model, self.data
        fid = self.arm.tool_frame
        joint_jacobians, frame_placement, frame_jacobian, log6, local = (
            pin.computeJointJacobians,
            pin.updateFramePlacement,
            pin.getFrameJacobian,
            pin.log6,
            pin.LOCAL,
        )
        tol2 = tol * tol
        best, stalled = math.inf, 0
        for _ in range(max_iter):
            joint_jacobians(model, data, q)  # also the joint placements oMi
            err = log6(frame_placement(model, data, fid).actInv(target)).vector
            e2 = float(err @ err)
            if e2 < tol2:
                return q
            # far from the target, < 10 % progress for a few steps means a local minimum or a
            # limit: give up and let a restart try; close to it (near-singular targets converge
            # linearly) keep going
            if e2 < 0.9 * best:
                best, stalled = e2, 0
            elif e2 > 1e-6:
                stalled += 1
                if stalled >= _STALL_STEPS:
                    return None
            J = frame_jacobian(model, data, fid, local)
            A = J @ J.T
            A.flat[::7] += _LM_DAMPING * e2 + _LM_DAMPING_FLOOR
            dq = J.T @ lapack.dposv(A, err)[1]
            big = float(np.abs(dq).max())
            if big > max_step:
                dq *= max_step / big
            q = q + dq
            if ((q < lo) | (q > hi)).any():
                wrapped = np.where(q > hi, q - 2 * math.pi, np.where(q < lo, q + 2 * math.pi, q))
                q = np.clip(np.where(cont, wrapped, q), lo, hi)
        return None

    def solve_ik(
        self,
        T_base_tool: ArrayLike,
        seed: ArrayLike,
        *,
        method: str = "auto",
        min_manipulability: float = DEFAULT_MIN_MANIPULABILITY,
        rng: np.random.Generator | None = None,
    ) -> IKSolution:
        """The IK solution nearest ``seed`` within limits, preferring non-singular ones.

        ``method``: ``analytic`` (closed form, UR-structure arms), ``numeric`` (LM with
        restarts), ``auto`` (analytic when available). Among analytic solutions, those with
        manipulability below ``min_manipulability`` are used only when nothing else exists.
        """
        T = check_pose(T_base_tool)
        q_seed = joint_vector(seed, self.dof, "seed")
        if method not in ("auto", "analytic", "numeric"):
            raise InvalidInputError(f"unknown IK method {method!r} (auto, analytic, numeric)")
        use_analytic = method == "analytic" or (method == "auto" and self.has_analytic_ik())
        if use_analytic:
            sols = self.ik_analytic(T, q_seed)
            if sols.shape[0] == 0:
                raise IKFailureError(
                    f"{self.spec.name}: no inverse-kinematics solution within joint limits for the tool at "
                    f"{pose_text(T)}"
                )
            measures = [self.manipulability(q) for q in sols]
            pick = next((k for k, m in enumerate(measures) if m >= min_manipulability), 0)
            q, m, how = sols[pick], measures[pick], "analytic"
        else:
            q = self.ik_numeric(T, q_seed, rng=rng)
            m, how = self.manipulability(q), "numeric"
        pos_err, rot_err = self.pose_error(q, T)
        return IKSolution(
            q=q, manipulability=m, method=how, position_error_m=pos_err, rotation_error_rad=rot_err
        )
