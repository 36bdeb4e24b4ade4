"""Dashboard reply parsing with byte fixtures: partial reads, several replies, garbage."""

import pytest

from services import dobot


def test_single_reply():
    r = dobot.parse_reply("0,{5},MovJ(joint={1,2,3,4,5,6});")
    assert r.ok and r.result_id == 5 and r.echo == "MovJ(joint={1,2,3,4,5,6})"


def test_empty_braces_mean_no_result_id():
    r = dobot.parse_reply("0,{},MovJ(pose={150.000000,0,0,0,0,0});")
    assert r.result_id is None
    assert r.values() == []


def test_partial_data_waits_for_more_bytes():
    p = dobot.ReplyParser()
    data = b"0,{-0.000000,-350.000000,300.000000,92.000000,67.000000,107.000000},GetPose();"
    for cut in (1, 3, 10, 40, len(data) - 1):
        p = dobot.ReplyParser()
        assert p.feed(data[:cut]) == []
        items = p.feed(data[cut:])
        assert len(items) == 1 and isinstance(items[0], dobot.Reply)
        assert items[0].floats() == [-0.0, -350.0, 300.0, 92.0, 67.0, 107.0]


def test_two_replies_in_one_read():
    items = dobot.ReplyParser().feed(b"0,{},EnableRobot();0,{7},MovJ(joint={0,0,0,0,0,0});")
    assert [type(i) for i in items] == [dobot.Reply, dobot.Reply]
    assert items[0].command_name == "EnableRobot" and items[1].result_id == 7


def test_error_reply_and_description():
    r = dobot.parse_reply("-30001,{},MovJ(joint={10.000,20.000,30.000,0.000,0.000,0.000},a=20,v=50);")
    assert r.error_id == -30001 and not r.ok
    assert "type of required parameter 1" in dobot.describe_error_id(r.error_id)
    assert "alarm" in dobot.describe_error_id(-2)


@pytest.mark.parametrize(
    "values, expected",
    [
        ("[[117],[],[],[],[],[],[]]", [117]),  # V4.5.1 shape
        ("[[],[],[],[],[],[],[]]", []),
        ("[16,68]", [16, 68]),  # V4.6 shape
        ("[]", []),
        ("", []),
    ],
)
def test_get_error_id_both_shapes(values, expected):
    r = dobot.parse_reply(f"0,{{{values}}},GetErrorID();")
    assert dobot.parse_error_ids(r.values_text) == expected


def test_garbage_is_reported_and_stream_continues():
    p = dobot.ReplyParser()
    items = p.feed(b"hello world;0,{4},RobotMode();")
    assert isinstance(items[0], dobot.Unparseable)
    assert isinstance(items[1], dobot.Reply) and items[1].floats() == [4.0]


def test_not_tcp_mode_text():
    items = dobot.ReplyParser().feed(b"Control Mode Is Not Tcp")
    assert len(items) == 1 and isinstance(items[0], dobot.Unparseable)
    assert "TCP/IP control mode" in items[0].reason


def test_reply_with_spaces_in_echo():
    r = dobot.parse_reply("0,{},GetPose(user = 1, tool = 0);")
    assert r.echo == "GetPose(user = 1, tool = 0)"
