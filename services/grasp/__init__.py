"""Grasp planning: antipodal synthesis with force closure, and task-level waypoint plans.

Pure cores (numpy in, dataclasses out): :mod:`force_closure` (friction cones, Ferrari–Canny ε),
:mod:`synthesis` (box / cylinder / sphere grasps, quality, reachability), :mod:`rod`
(pick-and-stand), :mod:`cube` (pick-and-place to colour-keyed drop zones). :mod:`service` is the
thin ``GraspPlanner`` gRPC shell.
"""

from services.grasp.cube import CubeObservation, drop_zone, plan_pick_and_place
from services.grasp.force_closure import (
    ContactModel,
    ForceClosureResult,
    evaluate_force_closure,
    ferrari_canny,
)
from services.grasp.plan import Grasp, Guard, HeldObject, PickPlan, Waypoint
from services.grasp.rod import RodObservation, plan_pick_and_stand
from services.grasp.synthesis import GraspSet, ObjectSpec, compute_grasps

__all__ = [
    "ContactModel",
    "CubeObservation",
    "ForceClosureResult",
    "Grasp",
    "GraspSet",
    "Guard",
    "HeldObject",
    "ObjectSpec",
    "PickPlan",
    "RodObservation",
    "Waypoint",
    "compute_grasps",
    "drop_zone",
    "evaluate_force_closure",
    "ferrari_canny",
    "plan_pick_and_place",
    "plan_pick_and_stand",
]
