"""The 1440-byte feedback packet: layout offsets, framing, resynchronisation."""

import numpy as np
import pytest

from services import dobot


def _packet(mode: int = 5, cmd_id: int = 0, q=(1, 2, 3, 4, 5, 6)) -> bytes:
    rec = dobot.new_feedback()
    rec["RobotMode"] = mode
    rec["CurrentCommandId"] = cmd_id
    rec["QActual"] = q
    rec["CRRobotType"] = 103
    return dobot.encode_feedback(rec)


def test_feedback_layout_offsets():
    data = _packet(mode=7, cmd_id=42)
    assert len(data) == 1440
    assert data[0:2] == b"\xa0\x05"
    assert data[48:56] == bytes.fromhex("efcdab8967452301")
    assert int.from_bytes(data[24:32], "little") == 7
    assert int.from_bytes(data[1112:1120], "little") == 42
    assert np.frombuffer(data[432:480], "<f8").tolist() == [1, 2, 3, 4, 5, 6]
    assert data[1031] == 103
    rec = dobot.decode_feedback(data)
    assert int(rec["RobotMode"]) == 7


def test_feedback_framer_resynchronises():
    f = dobot.FeedbackFramer()
    a, b, c = _packet(cmd_id=1), _packet(cmd_id=2), _packet(cmd_id=3)
    stream = a[:700] + b"\x00\x13\xa0\x05garbage" + b + c[:100]
    out = f.feed(stream[:500]) + f.feed(stream[500:])
    assert [int(r["CurrentCommandId"]) for r in out] == [2]
    assert f.resyncs >= 1
    out = f.feed(c[100:])
    assert [int(r["CurrentCommandId"]) for r in out] == [3]


def test_feedback_framer_several_packets_one_read():
    f = dobot.FeedbackFramer()
    out = f.feed(b"".join(_packet(cmd_id=i) for i in range(5)))
    assert [int(r["CurrentCommandId"]) for r in out] == [0, 1, 2, 3, 4]
    assert f.resyncs == 0


def test_decode_rejects_bad_packet():
    bad = bytearray(_packet())
    bad[50] ^= 0xFF
    with pytest.raises(dobot.ProtocolError):
        dobot.decode_feedback(bytes(bad))
    with pytest.raises(dobot.ProtocolError):
        dobot.decode_feedback(b"\x00" * 10)
