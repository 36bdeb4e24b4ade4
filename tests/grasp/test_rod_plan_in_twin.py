"""Rod pick-and-stand plans executed in the MuJoCo twin: the rod really ends standing (ground truth)."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest

from bench.bench_grasp import run_twin_trials


@pytest.mark.parametrize("seed", [3, 8])
def test_planned_pick_and_stand_stands_the_rod_in_the_twin(seed: int) -> None:
    (r,) = run_twin_trials([seed])
    assert r["success"] == 1.0, r.get("reasons")
    assert r["touch_detected"] == 1.0  # the guarded descent stopped on the wrist-force drop
    assert r["tilt_before_release_deg"] < 3.0  # the notes: placement tilt must stay below ~3°
    assert r["slip_mm"] < 5.0 and r["slip_deg"] < 2.0
