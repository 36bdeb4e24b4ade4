"""Sampling-based joint-space planning with OMPL (RRTConnect, RRTstar, PRM — LLD §5.1).

The collision checker is OMPL's state validity checker; motions are checked at the
given joint resolution. The found path is shortcut and smoothed by OMPL's path
simplifier (which re-checks every change), within the same time budget.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from services.common.errors import InvalidInputError, PathPlanningTimeoutError
from services.kinematics.trajectory import Array, JointLimits


def _rrt_star(si: ob.SpaceInformation) -> ob.Planner:
    planner = og.RRTstar(si)
    # LLD §5.1: goal bias 0.05, rewire factor 1.1. Radius-based rewiring: OMPL's k-nearest default
    # starts at hundreds of neighbours in 6-D, each a Python collision check here
    planner.setGoalBias(0.05)
    planner.setRewireFactor(1.1)
    planner.setKNearest(False)
    planner.setRange(0.8)
    return planner


def _prm(si: ob.SpaceInformation) -> ob.Planner:
    planner = og.PRM(si)
    planner.setMaxNearestNeighbors(10)  # LLD §5.1
    return planner


PLANNERS: dict[str, Callable[[ob.SpaceInformation], ob.Planner]] = {
    "RRTConnect": og.RRTConnect,
    "RRTstar": _rrt_star,
    "PRM": _prm,
}

ou.setLogLevel(ou.LOG_WARN)
_planning_seed: int | None = None


def seed_planning(seed: int) -> int:
    """Seed OMPL's random numbers for this process, so plans repeat from run to run; returns the seed
    in effect. OMPL takes a seed only before its first random number, so the first call wins and
    later ones (another planner, another seed) leave it as it is."""
    global _planning_seed
    if _planning_seed is None:
        if seed < 0:
            raise InvalidInputError(f"planning seed must be >= 0, got {seed}")
        ou.RNG.setSeed(seed % (2**32 - 1) + 1)  # OMPL ignores a seed of 0
        _planning_seed = seed
    return _planning_seed


def sampling_bounds(
    limits: JointLimits, start: Array, goal: Array, margin: float = math.pi
) -> tuple[Array, Array]:
    """The box OMPL samples in: the start–goal box grown by ``margin`` on every joint, within limits."""
    lo = np.maximum(limits.lower, np.minimum(start, goal) - margin)
    hi = np.minimum(limits.upper, np.maximum(start, goal) + margin)
    return lo, hi


def _shorten(simplifier: og.PathSimplifier, path: og.PathGeometric, effort: int) -> None:
    """Cheap shortcutting: drop vertices that see each other, then a few partial shortcuts."""
    simplifier.reduceVertices(path)
    for _ in range(effort):
        changed = simplifier.partialShortcutPath(path, 20, 10)
        changed |= simplifier.reduceVertices(path)
        if not changed:
            break


class _SegmentValidator(ob.MotionValidator):
    """OMPL motion validator that defers to our segment check (max-norm joint resolution,
    bisection order) instead of OMPL's Euclidean discretisation, which checks about twice
    as many states for the same per-joint step."""

    def __init__(self, si: ob.SpaceInformation, dof: int, segment_free: Callable[[Array, Array], bool]):
        super().__init__(si)
        self._dof = dof
        self._segment_free = segment_free

    def checkMotion(self, s1: ob.State, s2: ob.State, *_last_valid: object) -> bool:  # OMPL API name
        n = self._dof
        a = np.fromiter((s1[i] for i in range(n)), dtype=float, count=n)
        b = np.fromiter((s2[i] for i in range(n)), dtype=float, count=n)
        return self._segment_free(a, b)


def plan_path(
    is_valid: Callable[[Array], bool],
    limits: JointLimits,
    start: Array,
    goal: Array,
    *,
    planner: str = "RRTConnect",
    time_budget_s: float = 1.0,
    resolution_rad: float = math.radians(1.0),
    simplify: int = 2,
    segment_free: Callable[[Array, Array], bool] | None = None,
    margin: float = math.pi,
) -> Array:
    """A collision-free joint path (N, dof) from start to goal, or PathPlanningTimeoutError.

    ``is_valid(q)`` is the state validity test (True = collision-free);
    ``segment_free(a, b)``, when given, checks straight motions (else OMPL discretises
    them at ``resolution_rad``). ``simplify``: rounds of shortcutting (0 = none).
    """
    if planner not in PLANNERS:
        raise InvalidInputError(f"unknown planner {planner!r}; choose one of {sorted(PLANNERS)}")
    if not (math.isfinite(time_budget_s) and time_budget_s > 0):
        raise InvalidInputError(f"planning time budget must be positive, got {time_budget_s}")
    t0 = time.perf_counter()
    dof = limits.dof
    space = ob.RealVectorStateSpace(dof)
    bounds = ob.RealVectorBounds(dof)
    lo, hi = sampling_bounds(limits, start, goal, margin)
    for i in range(dof):
        bounds.setLow(i, float(lo[i]))
        bounds.setHigh(i, float(hi[i]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)

    def valid(state: ob.State) -> bool:
        return is_valid(np.fromiter((state[i] for i in range(dof)), dtype=float, count=dof))

    si.setStateValidityChecker(valid)
    # OMPL checks motions at a fraction of the space's largest extent (a Euclidean length, which
    # bounds every single joint's step too)
    si.setStateValidityCheckingResolution(min(0.5, resolution_rad / space.getMaximumExtent()))
    validator = _SegmentValidator(si, dof, segment_free) if segment_free is not None else None
    if validator is not None:
        si.setMotionValidator(validator)
    si.setup()
    setup = og.SimpleSetup(si)
    a = space.allocState()
    b = space.allocState()
    for i in range(dof):
        a[i] = float(start[i])
        b[i] = float(goal[i])
    # a goal tolerance far below the collision resolution; the path end is snapped to the goal
    setup.setStartAndGoalStates(a, b, 1e-6)
    setup.setPlanner(PLANNERS[planner](si))
    setup.setup()
    # early termination (LLD §16.1): stop at the first exact solution (RRTConnect, PRM) instead of
    # using the whole budget; shortcutting below then improves the path
    # (RRTstar is anytime: it reports its solution only when the budget is spent)
    ptc = ob.plannerOrTerminationCondition(
        ob.timedPlannerTerminationCondition(time_budget_s),
        ob.exactSolnPlannerTerminationCondition(setup.getProblemDefinition()),
    )
    status = setup.solve(ptc)
    if not setup.haveExactSolutionPath():
        elapsed = time.perf_counter() - t0
        raise PathPlanningTimeoutError(
            f"{planner} found no collision-free joint path within {elapsed:.2f} s (budget {time_budget_s:.2f} s, "
            f"status {status})"
        )
    path = setup.getSolutionPath()
    if simplify:
        _shorten(og.PathSimplifier(si), path, simplify)
    out = np.array([[path.getState(k)[i] for i in range(dof)] for k in range(path.getStateCount())])
    out[0], out[-1] = start, goal
    return out
