"""The controller-side command framer and parser."""

import pytest

from services import dobot


def test_command_framer_splits_and_waits():
    f = dobot.CommandFramer()
    assert f.feed(b"EnableRobot()MovJ(joint={1,2,3") == ["EnableRobot()"]
    assert f.feed(b",4,5,6},v=10)GetAngle(") == ["MovJ(joint={1,2,3,4,5,6},v=10)"]
    assert f.feed(b")") == ["GetAngle()"]
    # a line without parentheses still gets cut so it can be answered
    assert f.feed(b"garbage\n") == ["garbage"]


def test_parse_command_args_and_keywords():
    c = dobot.parse_command("MovJ(joint = {1, 2, 3, 4, 5, 6}, a=20 ,v = 50)")
    assert c.key == "movj" and c.args == []
    assert c.kwargs == {"joint": "{1, 2, 3, 4, 5, 6}", "a": "20", "v": "50"}
    c = dobot.parse_command("ServoJ(1,2,3,4,5,6,t=0.1)")
    assert c.args == ["1", "2", "3", "4", "5", "6"] and c.kwargs == {"t": "0.1"}
    assert dobot.parse_point("{1,2,3,4,5,6}") == [1, 2, 3, 4, 5, 6]
    with pytest.raises(dobot.ProtocolError):
        dobot.parse_command("not a command")
