"""Which cycle state each waypoint of a grasp plan belongs to (pure)."""

from __future__ import annotations

from services.task.states import CycleState

# Which cycle state a grasp-plan waypoint belongs to (seed 001 §3.5 names).
WAYPOINT_STATE: dict[str, CycleState] = {
    "SAFE_HOME": CycleState.APPROACH,
    "PRE_GRASP": CycleState.APPROACH,
    "GRASP": CycleState.GRASP,
    "LIFT": CycleState.LIFT,
    "REORIENT": CycleState.REORIENT,
    "TRANSPORT": CycleState.TRANSPORT,
    "CARRY": CycleState.PLACE,
    "PRE_PLACE": CycleState.PLACE,
    "PLACE": CycleState.PLACE,
    "RELEASE": CycleState.RELEASE,
    "RETRACT": CycleState.RELEASE,
    "HOME": CycleState.DONE,
}


def state_for(waypoint_name: str) -> CycleState:
    name = waypoint_name.upper()
    if name in WAYPOINT_STATE:
        return WAYPOINT_STATE[name]
    for prefix, state in WAYPOINT_STATE.items():
        if name.startswith(prefix):
            return state
    return CycleState.APPROACH
