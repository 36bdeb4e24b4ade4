"""Controller codes: alarm numbering and texts."""

from services import dobot


def test_alarm_numbering():
    assert dobot.joint_limit_alarm(0, True) == 64 and dobot.joint_limit_alarm(5, False) == 75
    assert "joint 3 positive" in dobot.describe_alarm(68)
    assert dobot.describe_alarm(117) == "collision detected"
