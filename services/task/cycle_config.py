"""What a pick cycle is allowed and where it works: retry budgets, deadlines, the place region, the grasp
offsets tried along a rod and the safe home (built from the settings by services.task.runner)."""

from __future__ import annotations

from dataclasses import dataclass, field

from services.task.recovery import RetryLimits
from services.task.states import StateDeadlines


@dataclass(frozen=True)
class CycleConfig:
    limits: RetryLimits = field(default_factory=RetryLimits)
    deadlines: StateDeadlines = field(default_factory=StateDeadlines)
    detect_retry_delay_s: float = 0.5
    verify_grasp: bool = True  # check the gripper's object signal after LIFT
    place_xy: tuple[float, float] | None = (0.45, 0.0)  # None: the grasp service's configured spot
    place_region_min: tuple[float, float] = (0.35, -0.25)
    place_region_max: tuple[float, float] = (0.60, 0.25)
    place_clearance_m: float = 0.06
    grasp_offsets_m: tuple[float, ...] = (0.0, 0.035, -0.035, 0.055, -0.055, 0.075, -0.075)
    # the open jaws' footprint (along the rod, across it: motion.tool.finger_box_m) and the clearance
    # the planners keep from a seen box (motion.padding_m): offsets whose footprint meets a box go last
    jaw_footprint_m: tuple[float, float] = (0.03, 0.12)
    jaw_clearance_m: float = 0.01
    # a grasp approach the controller stopped on a contact (the fingertips on a table seen too low:
    # camera calibration error of +-0.5 deg is +-6 mm at the rod) is retried this much higher, each time
    contact_raise_m: float = 0.003
    # a guarded touch-down that found no contact within its overtravel goes on this much further, guarded
    touch_down_extension_m: float = 0.01
    home_joints: tuple[float, ...] | None = None  # rad; each cycle starts here (clear camera view)
    # a cycle that starts away from home first rises straight up to this tool height (m), clear of the
    # boxes on the table (an aborted cycle may have left the jaws beside one)
    home_rise_to_m: float = 0.25
    # rad/s², per joint: the driver's acceleration limits, which a retimed (paced) touch-down keeps
    max_joint_acceleration: tuple[float, ...] | None = None
    # the arm sets off toward the object, this high above it (m), while its grasp plans (0: it waits
    # for the plan at rest)
    set_off_height_m: float = 0.0
    # the set-off goes out in pieces, and once the grasp plan is in, flows on down the grasp line from
    # where the arm will be rather than stopping above the object (the jaws opened before it sets off)
    set_off_flows_on: bool = False
    servo_period_s: float = 0.03  # the driver's streaming period: the set-off's pieces end on it
    # how far the tool may leave the planned path where a blended run's corner is rounded (0: never)
    corner_tolerance_m: float = 0.0
    # a rod grasped this far off its centre (m; 0: never) is measured held above the place, and turned
    # straight when it leans more than straighten_min_deg (but not more than straighten_max_deg)
    straighten_from_offset_m: float = 0.0
    straighten_min_deg: float = 0.5
    straighten_max_deg: float = 12.0
    table_z_m: float = 0.0  # where vision need not look for the held rod below
