"""The grasp offsets along a rod are tried clear-footprint first: a neighbour beside the rod's centre no
longer costs a refused grasp-planning call per blocked offset."""

from __future__ import annotations

import numpy as np
import pytest

from services.task.grasp_offsets import jaw_footprint, order_offsets, overlaps
from services.task.ports import SeenBox
from tests.task.fakes import FakeCell, FakeVision, rod_at, seen

OFFSETS = (0.0, 0.035, -0.035, 0.055, -0.055, 0.075, -0.075)
ALONG, ACROSS, CLEAR = 0.03, 0.12, 0.01


def cube_at(x: float, y: float, half: float = 0.025) -> SeenBox:
    return SeenBox(np.array([x - half, y - half, 0.0]), np.array([x + half, y + half, 2 * half]))


def test_the_footprint_lies_across_the_rod_at_the_offset() -> None:
    corners = jaw_footprint(np.array([0.5, 0.1, 0.01]), np.array([1.0, 0.0, 0.0]), 0.035, ALONG, ACROSS)
    assert np.allclose(corners.min(axis=0), [0.52, 0.04]) and np.allclose(corners.max(axis=0), [0.55, 0.16])


@pytest.mark.parametrize(
    ("box", "hit"),
    [
        (cube_at(0.5, 0.1 + 0.06 + 0.025 + 0.009), True),  # 9 mm from the jaw: within the clearance
        (cube_at(0.5, 0.1 + 0.06 + 0.025 + 0.011), False),  # 11 mm: clear
        (cube_at(0.5 + 0.015 + 0.025 + 0.011, 0.1), False),  # beyond the jaw's end along the rod
    ],
)
def test_a_box_meets_the_footprint_within_the_clearance(box: SeenBox, hit: bool) -> None:
    corners = jaw_footprint(np.array([0.5, 0.1]), np.array([1.0, 0.0]), 0.0, ALONG, ACROSS)
    assert overlaps(corners, box, CLEAR) is hit


def test_a_rotated_footprint_misses_a_box_its_bounding_box_would_meet() -> None:
    # the rod at 45 deg: the footprint's axis-aligned bounds reach a box off its corner; the footprint does not
    corners = jaw_footprint(np.array([0.5, 0.1]), np.array([1.0, 1.0]), 0.0, ALONG, ACROSS)
    hi = corners.max(axis=0)
    box = SeenBox(np.array([hi[0] - 0.01, hi[1] - 0.01, 0.0]), np.array([hi[0] + 0.05, hi[1] + 0.05, 0.05]))
    assert np.all(box.min[:2] < hi) and not overlaps(corners, box, 0.0)


def test_blocked_offsets_go_last_in_their_configured_order() -> None:
    center, axis = np.array([0.5, 0.1]), np.array([1.0, 0.0])
    beside_centre = cube_at(0.5, 0.1 + 0.06 + 0.02)  # touches the jaws at offsets 0 and +-0.035
    got = order_offsets(OFFSETS, center, axis, [beside_centre], ALONG, ACROSS, CLEAR)
    assert got == (0.055, -0.055, 0.075, -0.075, 0.0, 0.035, -0.035)
    assert order_offsets(OFFSETS, center, axis, [], ALONG, ACROSS, CLEAR) == OFFSETS


async def test_a_cube_beside_the_rods_centre_is_grasped_around_at_the_first_plan() -> None:
    obs = seen(rod_at(0.5, 0.1))
    cube = cube_at(0.5, 0.1 + 0.06 + 0.02)
    cell = FakeCell(FakeVision(type(obs)(rods=obs.rods, obstacles=(cube,))))
    outcome = await cell.run()
    assert outcome.success and outcome.attempts == 1
    assert [c.grasp_offset_m for c in cell.grasp.calls] == [pytest.approx(0.055)]
