"""The questions a twin's ground truth answers across the simulated UR's pipe (light: no MuJoCo)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field


class TruthQuery(enum.StrEnum):
    """The questions :class:`services.sim.twin.ur_cell.EngineTruth` answers (its method names)."""

    ROD_STANDING = "rod_standing"
    CUBE_IN_ZONE = "cube_in_zone"
    OBJECT_VELOCITY = "object_velocity"
    OBJECT_TILT_DEG = "object_tilt_deg"
    SCENE_RECORD = "scene_record"


@dataclass(frozen=True)
class SceneRecord:
    seed: int
    layout_redraws: int  # layouts the scene sampler drew again before every object fitted
    randomization: dict[str, float] = field(default_factory=dict)  # the world's record ({} when nominal)
