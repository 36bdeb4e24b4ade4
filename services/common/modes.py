"""The modes the cell's services agree on, one enum each (pure).

StrEnums, so YAML, the CLI, REST and protobuf string fields keep carrying the same values
(``TaskKind("stand-rod") is TaskKind.STAND_ROD``; a member compares equal to its string).
"""

from __future__ import annotations

import enum


class TaskKind(enum.StrEnum):
    """What a pick cycle does with the object."""

    STAND_ROD = "stand-rod"  # pick the lying rod and stand it upright (seed 001)
    SORT_CUBES = "sort-cubes"  # pick a cube and put it in the drop zone of its colour (seed 004)

    @property
    def object_class(self) -> str:
        return "rod" if self is TaskKind.STAND_ROD else "cube"


class MotionKind(enum.StrEnum):
    """How the arm reaches a waypoint."""

    JOINT = "joint"  # a joint-space move (MovJ), planned around obstacles
    LINEAR = "linear"  # a straight tool line (MovL)
    HOLD = "hold"  # no motion: act where the arm stands (a gripper command at touch height)


class CubeRelease(enum.StrEnum):
    """How a sorted cube leaves the jaws over its drop zone."""

    DROP = "drop"  # let go a little above the highest table the cell allows for: no touch-down, no rest above
    TOUCH_DOWN = "touch-down"  # set down by a guarded descent that stops on the wrist force, then let go


class GripperCommand(enum.StrEnum):
    OPEN = "open"
    CLOSE = "close"
