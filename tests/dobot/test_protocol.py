"""Sans-I/O protocol tests with byte fixtures."""

import numpy as np
import pytest

from services.dobot import protocol as P


# ----------------------------------------------------------------------------- encoding
def test_command_encoding_matches_sdk_formats():
    assert P.mov_j_joint([10, 20, 30, 40, 50, 60], v=50) == (
        "MovJ(joint={10.000000,20.000000,30.000000,40.000000,50.000000,60.000000},v=50)"
    )
    assert P.mov_l_pose([1, 2, 3, 4, 5, 6], speed=200, v=20).startswith("MovL(pose={1.000000,")
    assert "speed=200" in P.mov_l_pose([1, 2, 3, 4, 5, 6], speed=200, v=20)
    assert "v=" not in P.mov_l_pose([1, 2, 3, 4, 5, 6], speed=200, v=20)  # speed wins over v
    assert (
        P.servo_j([0] * 6, t_s=0.03)
        == "ServoJ(0.000000,0.000000,0.000000,0.000000,0.000000,0.000000,t=0.030000)"
    )
    assert P.digital_output(1, True) == "DO(1,1)"
    assert P.digital_output(2, False, tool=True) == "ToolDO(2,0)"
    assert P.emergency_stop(True) == "EmergencyStop(1)"
    assert P.inverse_kin([1, 2, 3, 4, 5, 6], [0] * 6).endswith(
        ",useJointNear=1,jointNear={0.000000,0.000000,0.000000,0.000000,0.000000,0.000000})"
    )
    with pytest.raises(ValueError):
        P.mov_j_joint([0] * 6, v=50.5)  # ratios are integers, as in the SDK
    with pytest.raises(ValueError):
        P.speed_factor(0)


# ----------------------------------------------------------------------------- replies
def test_single_reply():
    r = P.parse_reply("0,{5},MovJ(joint={1,2,3,4,5,6});")
    assert r.ok and r.result_id == 5 and r.echo == "MovJ(joint={1,2,3,4,5,6})"


def test_empty_braces_mean_no_result_id():
    r = P.parse_reply("0,{},MovJ(pose={150.000000,0,0,0,0,0});")
    assert r.result_id is None
    assert r.values() == []


def test_partial_data_waits_for_more_bytes():
    p = P.ReplyParser()
    data = b"0,{-0.000000,-350.000000,300.000000,92.000000,67.000000,107.000000},GetPose();"
    for cut in (1, 3, 10, 40, len(data) - 1):
        p = P.ReplyParser()
        assert p.feed(data[:cut]) == []
        items = p.feed(data[cut:])
        assert len(items) == 1 and isinstance(items[0], P.Reply)
        assert items[0].floats() == [-0.0, -350.0, 300.0, 92.0, 67.0, 107.0]


def test_two_replies_in_one_read():
    items = P.ReplyParser().feed(b"0,{},EnableRobot();0,{7},MovJ(joint={0,0,0,0,0,0});")
    assert [type(i) for i in items] == [P.Reply, P.Reply]
    assert items[0].command_name == "EnableRobot" and items[1].result_id == 7


def test_error_reply_and_description():
    r = P.parse_reply("-30001,{},MovJ(joint={10.000,20.000,30.000,0.000,0.000,0.000},a=20,v=50);")
    assert r.error_id == -30001 and not r.ok
    assert "type of required parameter 1" in P.describe_error_id(r.error_id)
    assert "alarm" in P.describe_error_id(-2)


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
    r = P.parse_reply(f"0,{{{values}}},GetErrorID();")
    assert P.parse_error_ids(r.values_text) == expected


def test_garbage_is_reported_and_stream_continues():
    p = P.ReplyParser()
    items = p.feed(b"hello world;0,{4},RobotMode();")
    assert isinstance(items[0], P.Unparseable)
    assert isinstance(items[1], P.Reply) and items[1].floats() == [4.0]


def test_not_tcp_mode_text():
    items = P.ReplyParser().feed(b"Control Mode Is Not Tcp")
    assert len(items) == 1 and isinstance(items[0], P.Unparseable)
    assert "TCP/IP control mode" in items[0].reason


def test_reply_with_spaces_in_echo():
    r = P.parse_reply("0,{},GetPose(user = 1, tool = 0);")
    assert r.echo == "GetPose(user = 1, tool = 0)"


# ----------------------------------------------------------------------------- server side
def test_command_framer_splits_and_waits():
    f = P.CommandFramer()
    assert f.feed(b"EnableRobot()MovJ(joint={1,2,3") == ["EnableRobot()"]
    assert f.feed(b",4,5,6},v=10)GetAngle(") == ["MovJ(joint={1,2,3,4,5,6},v=10)"]
    assert f.feed(b")") == ["GetAngle()"]
    # a line without parentheses still gets cut so it can be answered
    assert f.feed(b"garbage\n") == ["garbage"]


def test_parse_command_args_and_keywords():
    c = P.parse_command("MovJ(joint = {1, 2, 3, 4, 5, 6}, a=20 ,v = 50)")
    assert c.key == "movj" and c.args == []
    assert c.kwargs == {"joint": "{1, 2, 3, 4, 5, 6}", "a": "20", "v": "50"}
    c = P.parse_command("ServoJ(1,2,3,4,5,6,t=0.1)")
    assert c.args == ["1", "2", "3", "4", "5", "6"] and c.kwargs == {"t": "0.1"}
    assert P.parse_point("{1,2,3,4,5,6}") == [1, 2, 3, 4, 5, 6]
    with pytest.raises(P.ProtocolError):
        P.parse_command("not a command")


# ----------------------------------------------------------------------------- feedback
def _packet(mode: int = 5, cmd_id: int = 0, q=(1, 2, 3, 4, 5, 6)) -> bytes:
    rec = P.new_feedback()
    rec["RobotMode"] = mode
    rec["CurrentCommandId"] = cmd_id
    rec["QActual"] = q
    rec["CRRobotType"] = 103
    return P.encode_feedback(rec)


def test_feedback_layout_offsets():
    data = _packet(mode=7, cmd_id=42)
    assert len(data) == 1440
    assert data[0:2] == b"\xa0\x05"
    assert data[48:56] == bytes.fromhex("efcdab8967452301")
    assert int.from_bytes(data[24:32], "little") == 7
    assert int.from_bytes(data[1112:1120], "little") == 42
    assert np.frombuffer(data[432:480], "<f8").tolist() == [1, 2, 3, 4, 5, 6]
    assert data[1031] == 103
    rec = P.decode_feedback(data)
    assert int(rec["RobotMode"]) == 7


def test_feedback_framer_resynchronises():
    f = P.FeedbackFramer()
    a, b, c = _packet(cmd_id=1), _packet(cmd_id=2), _packet(cmd_id=3)
    stream = a[:700] + b"\x00\x13\xa0\x05garbage" + b + c[:100]
    out = f.feed(stream[:500]) + f.feed(stream[500:])
    assert [int(r["CurrentCommandId"]) for r in out] == [2]
    assert f.resyncs >= 1
    out = f.feed(c[100:])
    assert [int(r["CurrentCommandId"]) for r in out] == [3]


def test_feedback_framer_several_packets_one_read():
    f = P.FeedbackFramer()
    out = f.feed(b"".join(_packet(cmd_id=i) for i in range(5)))
    assert [int(r["CurrentCommandId"]) for r in out] == [0, 1, 2, 3, 4]
    assert f.resyncs == 0


def test_decode_rejects_bad_packet():
    bad = bytearray(_packet())
    bad[50] ^= 0xFF
    with pytest.raises(P.ProtocolError):
        P.decode_feedback(bytes(bad))
    with pytest.raises(P.ProtocolError):
        P.decode_feedback(b"\x00" * 10)


def test_alarm_numbering():
    assert P.joint_limit_alarm(0, True) == 64 and P.joint_limit_alarm(5, False) == 75
    assert "joint 3 positive" in P.describe_alarm(68)
    assert P.describe_alarm(117) == "collision detected"
