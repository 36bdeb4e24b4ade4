"""proto ↔ grasp cores: the rod's size comes from the request (vision's measurement)."""

from __future__ import annotations

import logging
import math

import pytest
from pickplace.v1 import grasp_pb2

from services.common.errors import InvalidInputError
from services.common.modes import GripperCommand, MotionKind
from services.grasp.convert import GRIPPER, MOTION, rod_size


def test_the_measured_rod_size_is_used() -> None:
    req = grasp_pb2.PickAndStandRequest(length=0.19, diameter=0.021)
    assert rod_size(req, 0.2, 0.022) == (0.19, 0.021)


def test_the_configured_size_stands_in_only_for_a_missing_field_and_says_so(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.INFO, logger="pickplace.grasp.convert"):
        assert rod_size(grasp_pb2.PickAndStandRequest(length=0.19), 0.2, 0.022) == (0.19, 0.022)
    assert [r.getMessage() for r in caplog.records] == [
        "the request carries no rod diameter: planning with the configured 0.0220 m"
    ]


@pytest.mark.parametrize(
    ("length", "diameter"), [(0.0, 0.02), (-0.2, 0.02), (math.nan, 0.02), (0.2, math.inf)]
)
def test_a_measured_size_that_is_not_a_positive_length_is_refused(length: float, diameter: float) -> None:
    req = grasp_pb2.PickAndStandRequest(length=length, diameter=diameter)
    bad = "length" if not (math.isfinite(length) and length > 0) else "diameter"
    with pytest.raises(InvalidInputError, match=f"rod {bad} .* m: a measured size must be a positive number"):
        rod_size(req, 0.2, 0.022)


def test_waypoint_modes_map_to_their_proto_values() -> None:
    assert MOTION[MotionKind.HOLD] == grasp_pb2.PickWaypoint.HOLD
    assert GRIPPER[GripperCommand.CLOSE] == grasp_pb2.PickWaypoint.CLOSE
    assert MOTION["linear"] == grasp_pb2.PickWaypoint.LINEAR  # the StrEnum keeps its string's hash
