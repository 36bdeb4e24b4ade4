"""Seed 003's key-pose cycle (home → pre-grasp → grasp → lift → transport → place →
retreat → home): minimum-jerk moves, shortest-angle wrapping where the joint limits
allow it, a dwell at each pose. The placeholder job of ``pickplace up`` until the
real pick-and-place runs."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from services.common.settings import KeyPoseCycleSettings
from services.kinematics.interpolation import min_jerk_keypose_trajectory
from services.kinematics.trajectory import JointLimits
from services.robot.driver import RobotDriver


@dataclass
class CycleEvent:
    cycle: int
    step: int
    steps: int
    pose: str
    duration_s: float
    position_error_deg: float


@dataclass
class CycleReport:
    cycles: int = 0
    moves: int = 0
    total_s: float = 0.0
    max_position_error_deg: float = 0.0
    cycle_times_s: list[float] = field(default_factory=list)


async def run_keypose_cycle(
    driver: RobotDriver,
    cycle: KeyPoseCycleSettings,
    cycles: int,
    speed_ratio: int,
    on_event: Callable[[CycleEvent], None] | None = None,
) -> CycleReport:
    spec = driver.spec
    limits = JointLimits.from_spec(
        spec, velocity_scale=speed_ratio / 100.0, acceleration_scale=speed_ratio / 100.0
    )
    poses = {k: np.deg2rad(v) for k, v in cycle.poses_deg.items()}
    report = CycleReport()
    t_start = time.perf_counter()
    for c in range(1, cycles + 1):
        t_cycle = time.perf_counter()
        names = cycle.sequence
        # first get to the sequence's first pose from wherever the arm is
        targets = [names[0], *names[1:]]
        for i, name in enumerate(targets):
            q_now = driver.joint_positions()
            traj = min_jerk_keypose_trajectory(
                np.vstack([q_now, poses[name]]),
                cycle.move_duration_s,
                0.0,
                joint_names=spec.joint_names,
                limits=limits,
            )
            if traj.duration > 0 and np.max(np.abs(traj.positions[-1] - q_now)) > 1e-6:
                res = await driver.execute_trajectory(traj)
                dur = res.duration_s
            else:
                dur = 0.0
            err = float(np.rad2deg(np.max(np.abs(driver.joint_positions() - traj.positions[-1]))))
            report.moves += 1
            report.max_position_error_deg = max(report.max_position_error_deg, err)
            if on_event is not None:
                on_event(CycleEvent(c, i + 1, len(targets), name, dur, err))
            if cycle.dwell_s > 0:
                await asyncio.sleep(cycle.dwell_s)  # the dwell is the point: hold the pose
        report.cycles += 1
        report.cycle_times_s.append(time.perf_counter() - t_cycle)
    report.total_s = time.perf_counter() - t_start
    return report
