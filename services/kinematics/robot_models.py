"""Robot model data: standard DH tables, joint limits and speed limits (SI units).

Sources: ``shared/specs/dobot-v4-protocol-and-kinematics.md`` §6 (Nova5, DH derived
from the vendor URDF, verified against it) and §7 (UR5e/UR3 nominal DH and
``joint_limits.yaml``).

Nova5 velocity/acceleration limits are NOT published (the vendor URDF has
``velocity="0"``); the values below are our conservative choice: 120 °/s on the
three big joints and 180 °/s on the wrist, accelerations of 2.5x/3x those per
second. They are below UR5e's 180 °/s on every joint and can be raised in
``config/robots/limits.yaml`` once measured on hardware.

UR frames: the DH base frame of UR5e/UR3 is UR's controller ``base`` frame (URScript poses, the
teach pendant), and so is ``base_link`` in our URDFs; ROS ur_description's ``base_link`` is that
frame turned 180° about z. A pose taken from ROS tools must be turned by Rz(π) first.

UR3 wrist 3 is ±2π here, in the URDF and wherever limits are read (UR's datasheet calls it
"infinite"): a continuous URDF joint is a (cos, sin) pair in pinocchio, not one angle, which
the planner, the trajectory checks and the IK (one angle per joint) do not handle; ±2π is what
UR's own ROS description uses, and two full turns cover any pick-and-place motion because every
IK answer is unwrapped to the turn nearest its seed.

The DH tables are the *idealised* model (the simulated cell is built on it). The robot's own
model is its URDF (:mod:`services.kinematics.urdf`): the same frames for the URs, Dobot's joint
table for the Nova5, which differs from the table below by up to 6.3 µm at the flange.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from services.common.errors import ConfigurationError

ROBOTS_DIR = Path(__file__).resolve().parents[2] / "config" / "robots"


@dataclass(frozen=True)
class RobotSpec:
    name: str
    joint_names: tuple[str, ...]
    d: np.ndarray  # m
    a: np.ndarray  # m
    alpha: np.ndarray  # rad
    theta_offset: np.ndarray  # rad: theta_i = q_i + offset_i
    lower: np.ndarray  # rad
    upper: np.ndarray  # rad
    max_velocity: np.ndarray  # rad/s
    max_acceleration: np.ndarray  # rad/s^2
    max_jerk: np.ndarray  # rad/s^3
    reach_m: float
    robot_type_code: int = 0  # Dobot CRRobotType
    urdf: str = ""
    extra: dict[str, float] = field(default_factory=dict)

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    def continuous(self) -> np.ndarray:
        """Joints whose range spans at least a full turn (shortest-angle wrapping allowed)."""
        return (self.upper - self.lower) >= 2 * np.pi - 1e-9

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        return np.all((q >= self.lower - tol) & (q <= self.upper + tol), axis=-1)


def _deg(*v: float) -> np.ndarray:
    return np.deg2rad(np.array(v, dtype=float))


_HALF_PI = np.pi / 2

NOVA5 = RobotSpec(
    name="nova5",
    joint_names=("joint1", "joint2", "joint3", "joint4", "joint5", "joint6"),
    d=np.array([0.240, 0.0, 0.0, 0.135, 0.120, 0.088328]),
    a=np.array([0.0, 0.400, 0.330, 0.0, 0.0, 0.0]),
    alpha=np.array([_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0]),
    theta_offset=np.array([0.0, _HALF_PI, 0.0, _HALF_PI, 0.0, 0.0]),
    lower=np.array([-6.28, -3.14, -2.79, -6.28, -6.28, -6.28]),
    upper=np.array([6.28, 3.14, 2.79, 6.28, 6.28, 6.28]),
    max_velocity=_deg(120, 120, 120, 180, 180, 180),
    max_acceleration=_deg(300, 300, 300, 540, 540, 540),
    max_jerk=_deg(3000, 3000, 3000, 5400, 5400, 5400),
    reach_m=0.85,
    robot_type_code=103,
    urdf="nova5.urdf",
)

UR5E = RobotSpec(
    name="ur5e",
    joint_names=(
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ),
    d=np.array([0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996]),
    a=np.array([0.0, -0.425, -0.3922, 0.0, 0.0, 0.0]),
    alpha=np.array([_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0]),
    theta_offset=np.zeros(6),
    lower=np.array([-2 * np.pi, -2 * np.pi, -np.pi, -2 * np.pi, -2 * np.pi, -2 * np.pi]),
    upper=np.array([2 * np.pi, 2 * np.pi, np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi]),
    max_velocity=_deg(180, 180, 180, 180, 180, 180),
    max_acceleration=_deg(480, 480, 480, 480, 480, 480),
    max_jerk=_deg(4800, 4800, 4800, 4800, 4800, 4800),
    reach_m=0.85,
    urdf="ur5e.urdf",
)

UR3 = RobotSpec(
    name="ur3",
    joint_names=UR5E.joint_names,
    d=np.array([0.1519, 0.0, 0.0, 0.11235, 0.08535, 0.0819]),
    a=np.array([0.0, -0.24365, -0.21325, 0.0, 0.0, 0.0]),
    alpha=np.array([_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0]),
    theta_offset=np.zeros(6),
    lower=np.array([-2 * np.pi, -2 * np.pi, -np.pi, -2 * np.pi, -2 * np.pi, -2 * np.pi]),
    upper=np.array([2 * np.pi, 2 * np.pi, np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi]),
    max_velocity=_deg(180, 180, 180, 360, 360, 360),
    max_acceleration=_deg(480, 480, 480, 960, 960, 960),
    max_jerk=_deg(4800, 4800, 4800, 9600, 9600, 9600),
    reach_m=0.5,
    urdf="ur3.urdf",
)

ROBOTS: dict[str, RobotSpec] = {r.name: r for r in (NOVA5, UR5E, UR3)}


@functools.lru_cache(maxsize=8)
def get_robot(name: str) -> RobotSpec:
    """The model called ``name`` with the limits of ``config/robots/limits.yaml`` (read once)."""
    try:
        spec = ROBOTS[name]
    except KeyError as exc:
        raise ConfigurationError(f"unknown robot model {name!r}; known: {sorted(ROBOTS)}") from exc
    return _apply_limit_overrides(spec)


def _apply_limit_overrides(spec: RobotSpec) -> RobotSpec:
    """Velocity/acceleration limits from ``config/robots/limits.yaml`` (deg/s, deg/s^2), if given."""
    path = ROBOTS_DIR / "limits.yaml"
    if not path.exists():
        return spec
    data = (yaml.safe_load(path.read_text()) or {}).get(spec.name)
    if not data:
        return spec
    kw = {}
    for key in ("max_velocity", "max_acceleration", "max_jerk"):
        if key in data:
            vals = np.deg2rad(np.asarray(data[key], dtype=float))
            if vals.shape != (spec.dof,) or np.any(vals <= 0):
                raise ConfigurationError(f"{path}: {spec.name}.{key} needs {spec.dof} positive values")
            kw[key] = vals
    if not kw:
        return spec
    from dataclasses import replace

    return replace(spec, **kw)
