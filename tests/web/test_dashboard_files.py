"""The dashboard's static tables agree with the code they describe."""

from __future__ import annotations

import re

from services.common.settings import REPO_ROOT
from services.dobot.codes import ALARM_TEXT

WEB = REPO_ROOT / "web" / "static"


def test_the_alarm_meanings_are_the_controller_codes_texts() -> None:
    text = (WEB / "alarms.js").read_text()
    table = {int(k): v for k, v in re.findall(r'^\s+(\d+): "([^"]*)",$', text, re.M)}
    assert table == ALARM_TEXT
    # the ranges describe_alarm computes are there too (joint overspeed, joint limits)
    assert "id >= 48 && id <= 53" in text and "id >= 64 && id <= 75" in text


def test_the_dashboard_state_rule_is_the_gateways() -> None:
    js = (WEB / "state.js").read_text()
    from gateway.status import TASK_STATUS_FRESH_S

    assert f"TASK_FRESH_MS = {int(TASK_STATUS_FRESH_S * 1000)}" in js
