"""Assemble the simulated Dobot from settings (engine choice, ports, clock)."""

from __future__ import annotations

import numpy as np

from services.common.settings import Settings
from services.kinematics.robot_models import get_robot
from services.sim.controller import ControllerConfig, SimController
from services.sim.dobot_server import SimDobotServer
from services.sim.engine import KinematicEngine, MotionEngine

HOME_DEG = (0.0, 0.0, 90.0, 0.0, -90.0, 0.0)
# beyond this speed the sim runs "as fast as it can": no host can feed a stream in step with it
WATCHDOG_MAX_SPEED = 100.0


def servo_watchdog_margin(margin_s: float | None, speed: float) -> float | None:
    """The ServoJ watchdog margin in sim time: the host's latency is wall time, which the controller
    sees ``speed`` times longer; off (None) when asked, or when the sim runs as fast as it can."""
    if margin_s is None or speed <= 0 or speed > WATCHDOG_MAX_SPEED:
        return None
    return margin_s * max(speed, 1.0)


def build_engine(settings: Settings, engine: str | None = None) -> MotionEngine:
    name = engine or settings.sim.engine
    if name == "kinematic":
        return KinematicEngine()
    if name == "twin":
        from services.sim.twin import create_twin_engine  # mujoco only when asked for

        return create_twin_engine(settings, seed=settings.sim.seed)
    raise ValueError(f"unknown sim engine {name!r} (kinematic | twin)")


def build_sim_server(
    settings: Settings,
    engine: str | None = None,
    q0_deg: tuple[float, ...] | None = None,
    ports: dict[str, int] | None = None,
) -> SimDobotServer:
    """The simulated controller + its sockets. ``ports`` overrides (0 = pick a free port)."""
    s = settings.sim
    spec = get_robot(settings.robot.model)
    eng = build_engine(settings, engine)
    if q0_deg is None:
        q0_deg = (
            settings.sim.twin.initial_joints_deg if (engine or settings.sim.engine) == "twin" else HOME_DEG
        )
    q0 = np.deg2rad(q0_deg)
    controller = SimController(
        spec,
        eng,
        ControllerConfig(
            max_joint_speed_deg_s=s.max_joint_speed_deg_s,
            max_joint_acc_deg_s2=s.max_joint_acc_deg_s2,
            robot_type=spec.robot_type_code or 103,
            servo_watchdog_margin_s=servo_watchdog_margin(s.servo_watchdog_margin_s, s.speed),
        ),
        q0=q0,
    )
    p = {"dashboard": s.dashboard_port, "feedback": s.feedback_port, "slow": s.slow_feedback_port}
    p.update(ports or {})
    return SimDobotServer(
        controller,
        s.host,
        p["dashboard"],
        p["feedback"],
        p["slow"],
        period_s=s.feedback_period_s,
        slow_period_s=s.slow_feedback_period_s,
        speed=s.speed,
    )
