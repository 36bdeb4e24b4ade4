"""What stands under the way a carried object goes (services.grasp.way)."""

from __future__ import annotations

import numpy as np
import pytest

from services.grasp.way import carry_height
from services.kinematics.collision import Box


@pytest.mark.parametrize(
    ("start", "end", "box", "under"),
    [
        # a box between the two bearings, at their radius: under the way
        ((0.45, 0.0), (0.0, 0.45), Box((0.30, 0.30, 0.0), (0.34, 0.34, 0.2)), True),
        # the same box when the way swings the other side round (bearings -90° .. 0°)
        ((0.45, 0.0), (0.0, -0.45), Box((0.30, 0.30, 0.0), (0.34, 0.34, 0.2)), False),
        # beyond the radii (+ margin): off the way
        ((0.45, 0.0), (0.0, 0.45), Box((0.70, 0.70, 0.0), (0.74, 0.74, 0.2)), False),
        # a long wall across the sector with its corners outside it: its middle is under the way
        ((0.45, 0.10), (0.45, -0.10), Box((0.40, -0.50, 0.0), (0.42, 0.50, 0.2)), True),
        # lower than the least height with its clearance: does not raise it
        ((0.45, 0.0), (0.0, 0.45), Box((0.30, 0.30, 0.0), (0.34, 0.34, 0.05)), False),
    ],
)
def test_the_way_counts_the_boxes_the_swing_passes_over(
    start: tuple[float, float], end: tuple[float, float], box: Box, under: bool
) -> None:
    h = carry_height(0.12, 0.03, np.array(start), np.array(end), 0.025, [box])
    assert h == pytest.approx(box.max[2] + 0.055 if under else 0.12)
