"""A small seeded slice of `pickplace eval` (the long runs belong to the command itself)."""

from __future__ import annotations

import json

import pytest

from services.apps.evaluation import MAX_SETTLE_S, SETTLE_S, run_eval, write_report
from tests.apps.conftest import cell_settings

pytestmark = [pytest.mark.integration, pytest.mark.slow]


async def test_eval_two_trials_reports_ground_truth(tmp_path):
    s = cell_settings(tmp_path, sim={"speed": 3.0})
    report = await run_eval(s, trials=2, seed=10, progress=False)
    assert len(report.results) == 2 and [r.seed for r in report.results] == [10, 11]
    for r in report.results:
        # success is the twin's verdict; a failure always says where and why
        assert r.success == (not r.ground_truth_reasons)
        assert r.success or (r.stage_reached and r.failure_reason)
        assert 0 < r.compute_time_s < r.cycle_time_s <= r.cycle_time_real_s
        assert SETTLE_S <= r.settle_s <= MAX_SETTLE_S  # judged after settling, at rest if it got there
    summary = report.summary()
    assert summary["success_rate"] == report.successes / 2
    out = tmp_path / "eval.json"
    write_report(report, out)
    data = json.loads(out.read_text())
    assert data["summary"]["trials"] == 2 and len(data["trials"]) == 2
    assert report.successes >= 1  # seeds 10 and 11 stand in the twin (measured 8/8 from seed 10)
