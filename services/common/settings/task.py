"""The task orchestrator."""

from __future__ import annotations

from pydantic import Field

from services.common.modes import TaskKind
from services.common.settings.base import Model


class TaskSettings(Model):
    """The task orchestrator: which job, retries (LLD §15.2) and per-state deadlines."""

    task: TaskKind = TaskKind.STAND_ROD
    detect_retries: int = Field(4, ge=0, le=20)  # waits 0.5, 1, 2, 4 s (doubling)
    detect_retry_delay_s: float = Field(0.5, ge=0, le=30)
    grasp_alternatives: int = Field(
        8,
        ge=1,
        le=48,
        description="plans tried per cycle (rod: 7 grasp points along it, then the next wrist option)",
    )
    alarm_recoveries: int = Field(2, ge=0, le=10)
    regrasps: int = Field(2, ge=0, le=10)
    verify_grasp: bool = True
    detect_deadline_s: float = Field(10.0, gt=0)
    plan_deadline_s: float = Field(30.0, gt=0)
    motion_deadline_s: float = Field(60.0, gt=0)
    gripper_deadline_s: float = Field(10.0, gt=0)
    status_rate_hz: float = Field(2.0, gt=0, le=50)
    pause_between_cycles_s: float = Field(0.5, ge=0, le=60)
    # Fractions of the joint speed/acceleration limits while carrying the object and on guarded moves.
    # Carrying at the full limits: in 10 seeded twin trials (seed 1000) the grasp held and the tilt before
    # release was no worse than at 0.4 (median 0.34°, max 1.42° against 0.17° / 2.46°), 1.7 s faster.
    holding_speed_scale: float = Field(1.0, gt=0, le=1)
    # Where the arm flows through a waypoint, the motion planner may round the corner so the arm need not
    # slow down for it, the tool leaving the planned path by at most this much; the rounded corner is
    # collision-checked (motion.padding_m from the table and the boxes) in both moves' scenes; the
    # corner at the end of the line out of a release is checked against the placed object in the next
    # move's scene (the line itself starts with it between the open jaws and has not got it).
    corner_tolerance_m: float = Field(
        0.01, ge=0, le=0.1, description="how far a blended corner may leave the planned path (0: not rounded)"
    )
    # a guarded line's planned speed; the task paces it (grasp: slow only through the last band)
    guarded_speed_scale: float = Field(0.5, gt=0, le=1)
    # A guarded touch-down that went its whole overtravel without feeling the contact goes on, guarded and
    # at the touch-down speed, this much further before letting go (0: let go where it ended). Seed 1007:
    # a table 4.8 mm below where it was seen and a rod held 7 mm off where the grasp was planned put the
    # contact 12 mm past nominal; the 10 mm overtravel ended 2.2 mm above the table and the rod was let go
    # in the air.
    touch_down_extension_m: float = Field(0.01, ge=0, le=0.05)
    # After an aborted cycle or a restart nothing is known of the table: the arm first rises straight up to
    # this tool-tip height, above every box of the cell, before its joint move home (sorting cubes, a joint
    # move home from beside the wall swept through it: alarm 117).
    home_rise_to_m: float = Field(0.25, ge=0, le=1.0)
    # After a cycle the arm stays where its retract leaves the camera's view of the pick zone clear (or
    # goes only as far toward the safe home as that takes), decided by projecting its collision model
    # into the camera (sim.twin.camera) against the pick zone (sim.twin.scene) raised to this height.
    park_out_of_view: bool = True
    # Once vision has seen the object the arm sets off toward a pose above it (the approach height, jaws
    # across a rod) while the grasp plans from there: the planning no longer holds the arm at rest.
    set_off_before_planned: bool = True
    # The set-off goes out in pieces; once the grasp plan is in, the rest of it and the grasp line are
    # planned as one motion from where the arm will be, and replace the pieces not yet sent: the arm does
    # not stop above the object (at 1x; at a faster twin the whole set-off is queued before the plan is
    # in). The jaws open before the arm sets off.
    set_off_flows_on: bool = True
    # A rod grasped this far or farther off its centre turns in the jaws as it is stood up (its weight
    # twists it: 1-6° in the twin). Held above the place, vision measures its axis; more than
    # straighten_min_deg off the vertical, the tool turns it straight before the touch-down (0: never
    # measured). A measure beyond straighten_max_deg is taken for a wrong one and not acted on.
    straighten_from_offset_m: float = Field(0.02, ge=0, le=0.2)
    straighten_min_deg: float = Field(0.5, ge=0, le=10)
    straighten_max_deg: float = Field(12.0, gt=0, le=30)
    view_zone_height_m: float = Field(0.06, ge=0, le=0.5)
    view_margin_px: float = Field(12.0, ge=0, le=200)
    # A fresh twin scene after each cycle in `pickplace up` (the simulated operator lays the rod down again).
    reset_scene_each_cycle: bool = True
