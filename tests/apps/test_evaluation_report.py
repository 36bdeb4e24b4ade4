"""The eval's figures: Wilson bounds, success per parameter bin, the console tables (pure, no cell)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from rich.console import Console

from services.apps.eval_report import print_report, sensitivity, wilson_interval, worst_bin_rate
from services.apps.evaluation import EvalReport, TrialResult, execution_bound
from services.kinematics.robot_models import NOVA5
from services.kinematics.trajectory import JointLimits


def trial(seed: int, ok: bool, **record: float) -> TrialResult:
    return TrialResult(
        seed=seed,
        success=ok,
        task_success=ok,
        stage_reached="DONE" if ok else "GRASP",
        failure_reason="" if ok else "controller alarm 117",
        error_code="" if ok else "ControllerError",
        cycle_time_s=10.0,
        compute_wall_s=1.0,
        compute_controller_s=2.0,
        cycle_time_1x_s=9.0,
        attempts=1,
        randomization=dict(record),
    )


@pytest.mark.parametrize(
    ("k", "n", "lo", "hi"),
    [
        (0, 10, 0.0, 0.2775),
        (10, 10, 0.7225, 1.0),
        (5, 10, 0.2366, 0.7634),
        (995, 1000, 0.98837, 0.99786),  # 99.5 % over 1,000: the lower bound the issue asks to print
        (300, 300, 0.98736, 1.0),
    ],
)
def test_wilson_interval_matches_the_closed_form(k: int, n: int, lo: float, hi: float) -> None:
    a, b = wilson_interval(k, n)
    assert a == pytest.approx(lo, abs=2e-4) and b == pytest.approx(hi, abs=2e-4)
    assert a <= k / n <= b


def test_wilson_interval_refuses_impossible_counts() -> None:
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(11, 10)
    assert wilson_interval(0, 0) == (0.0, 1.0)


def test_sensitivity_counts_each_trial_in_the_bin_of_its_value() -> None:
    ranges = {"table_height_mm": (-5.0, 5.0), "pad_friction": (0.6, 1.2)}
    outcomes = [
        ({"table_height_mm": -4.0, "pad_friction": 0.7}, True),
        ({"table_height_mm": -1.0, "pad_friction": 1.19}, True),
        ({"table_height_mm": 3.0, "pad_friction": 0.9}, False),
        ({"table_height_mm": 4.9, "pad_friction": 1.0}, False),
        ({"table_height_mm": 7.0, "pad_friction": 0.61}, True),  # outside the range: the edge bin
    ]
    table = sensitivity(outcomes, ranges, bins=4)
    th = table["table_height_mm"]
    assert [b["trials"] for b in th] == [1, 1, 0, 3]
    assert [b["successes"] for b in th] == [1, 1, 0, 1]
    assert th[2]["rate"] is None and th[3]["rate"] == pytest.approx(1 / 3)
    assert th[0]["lo"] == -5.0 and th[3]["hi"] == 5.0
    assert th[3]["wilson_low"] == pytest.approx(wilson_interval(1, 3)[0])
    assert sum(b["trials"] for b in table["pad_friction"]) == 5
    assert worst_bin_rate(th) == pytest.approx(1 / 3)


def test_report_prints_the_interval_and_the_weakest_parameter_first() -> None:
    ranges = {"table_height_mm": (-5.0, 5.0), "light_scale": (0.6, 1.4)}
    results = [
        trial(0, True, table_height_mm=-4.0, light_scale=0.7),
        trial(1, True, table_height_mm=-2.0, light_scale=1.3),
        trial(2, False, table_height_mm=4.0, light_scale=0.7),  # shares its light bin with a success
        trial(3, True, table_height_mm=1.0, light_scale=1.1),
    ]
    report = EvalReport(
        task="stand-rod", trials=4, seed=0, successes=3, results=results, randomized=True, ranges=ranges
    )
    s = report.summary()
    assert s["success_ci95"] == pytest.approx(wilson_interval(3, 4))
    assert set(s["sensitivity"]) == set(ranges) and s["randomized"]
    console = Console(record=True, width=200)
    print_report(report, console)
    text = console.export_text()
    assert "success 95 % interval (Wilson)" in text and "randomized worlds" in text
    lines = [
        ln for ln in text.splitlines() if ln.startswith("│ table_height_mm") or ln.startswith("│ light_scale")
    ]
    assert lines[0].startswith("│ table_height_mm")  # 0/1 in its top bin: the weakest row comes first
    data = json.loads(report.to_json())
    assert data["trials"][2]["randomization"]["table_height_mm"] == 4.0
    assert data["summary"]["sensitivity"]["table_height_mm"][3]["successes"] == 0


def test_a_nominal_report_has_no_sensitivity() -> None:
    report = EvalReport(task="stand-rod", trials=1, seed=0, successes=1, results=[trial(0, True)])
    s = report.summary()
    assert not s["randomized"] and s["sensitivity"] == {} and s["randomization_ranges"] == {}


def test_the_bound_rests_where_the_arm_rested_and_counts_a_release_at_its_time():
    limits, names = JointLimits.from_spec(NOVA5), list(NOVA5.joint_names)
    home = np.deg2rad([180.0, 0.0, 90.0, 0.0, -90.0, 0.0])
    wps = [(home + np.deg2rad([d, 0, 0, 0, 0, 0])).tolist() for d in (0, 30, 60)]
    flowed = execution_bound(wps, [True, False, True], limits, names, 2, 0.4, releases=1, release_s=0.12)
    stopped = execution_bound(wps, [], limits, names, 2, 0.4)  # no rests recorded: at rest at each
    assert flowed.motion_s < stopped.motion_s == pytest.approx(stopped.rest_to_rest_motion_s)
    assert flowed.rest_to_rest_motion_s == pytest.approx(stopped.rest_to_rest_motion_s)
    assert flowed.gripper_s == pytest.approx(0.4 + 0.12) and stopped.gripper_s == pytest.approx(0.8)
    assert flowed.total_s == pytest.approx(flowed.motion_s + flowed.gripper_s)
    # what the driver checks (speed and acceleration) allows less, never more
    assert flowed.gripper_s < flowed.accel_limited_s < flowed.total_s


def test_the_bound_charges_a_touch_down_its_pace_where_the_joints_could_go_faster():
    from services.apps.evaluation import line_floors
    from services.kinematics import analytic
    from services.task.pacing import LinePace

    limits, names = JointLimits.from_spec(NOVA5), list(NOVA5.joint_names)
    home = np.deg2rad([180.0, 30.0, 90.0, 0.0, -90.0, 0.0])
    # a small joint-2 step: a few centimetres of tool travel, which the joints do in a fraction of a second
    wps = [home.tolist(), (home + np.deg2rad([0, 3, 0, 0, 0, 0])).tolist()]
    ends = analytic.fk(NOVA5, np.asarray(wps))[:, :3, 3]
    travel = float(np.linalg.norm(ends[1] - ends[0]))
    pace = LinePace(0.2, 0.025, travel - 0.006, 1.0)
    floors = line_floors(wps, {1: pace}, NOVA5)
    assert floors == {1: pytest.approx(pace.least_s(travel))}
    joints = execution_bound(wps, [True, True], limits, names, 0, 0.4)
    paced = execution_bound(wps, [True, True], limits, names, 0, 0.4, line_floors=floors)
    assert paced.motion_s == pytest.approx(joints.motion_s) and joints.pace_s == 0.0
    assert paced.pace_s == pytest.approx(floors[1] - joints.motion_s) and paced.pace_s > 0.2
    assert paced.total_s == pytest.approx(floors[1])
    # without the jerk limit the joints go faster still; the touch-down's pace does not
    assert joints.accel_limited_s < joints.total_s and paced.accel_limited_s == pytest.approx(floors[1])
