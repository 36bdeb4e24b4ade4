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


def _rec(**fields: object) -> np.ndarray:
    rec = dobot.decode_feedback(_packet())
    rec = rec.copy()
    rec["TimeStamp"] = 1_000
    for k, v in fields.items():
        rec[k] = v
    return rec


def test_sound_packet_has_no_fault():
    assert dobot.feedback_fault(_rec(), None) is None
    assert dobot.feedback_fault(_rec(), 992) is None
    assert dobot.feedback_fault(_rec(), 1_000) is None  # a repeated stamp is still monotonic


@pytest.mark.parametrize(
    ("field", "value", "why"),
    [
        ("QActual", [np.nan, 0, 0, 0, 0, 0], "QActual not finite"),
        ("QTarget", [0, 0, np.inf, 0, 0, 0], "QTarget not finite"),
        ("QActual", [0, 0, 0, 0, 0, 1e6], "QActual beyond"),
        ("QDActual", [0, np.nan, 0, 0, 0, 0], "QDActual not finite"),
        ("QDActual", [0, 5000, 0, 0, 0, 0], "QDActual beyond"),
        ("ToolVectorActual", [np.nan, 0, 0, 0, 0, 0], "ToolVectorActual not finite"),
        ("ToolVectorActual", [1e9, 0, 0, 0, 0, 0], "ToolVectorActual implausible"),
        ("ActualTCPForce", [0, 0, np.nan, 0, 0, 0], "ActualTCPForce"),
        ("RobotMode", 77, "RobotMode 77 unknown"),
    ],
)
def test_non_finite_or_implausible_values_are_faults(field, value, why):
    fault = dobot.feedback_fault(_rec(**{field: value}), None)
    assert fault is not None and why in fault


def test_controller_clock_must_not_run_backwards_or_leap():
    assert "backwards" in str(dobot.feedback_fault(_rec(), 1_008))
    assert "leapt" in str(dobot.feedback_fault(_rec(TimeStamp=2**62), 1_000))
