"""Command encoding in the SDK's formats."""

import pytest

from services import dobot


def test_command_encoding_matches_sdk_formats():
    assert dobot.mov_j_joint([10, 20, 30, 40, 50, 60], v=50) == (
        "MovJ(joint={10.000000,20.000000,30.000000,40.000000,50.000000,60.000000},v=50)"
    )
    assert dobot.mov_l_pose([1, 2, 3, 4, 5, 6], speed=200, v=20).startswith("MovL(pose={1.000000,")
    assert "speed=200" in dobot.mov_l_pose([1, 2, 3, 4, 5, 6], speed=200, v=20)
    assert "v=" not in dobot.mov_l_pose([1, 2, 3, 4, 5, 6], speed=200, v=20)  # speed wins over v
    assert (
        dobot.servo_j([0] * 6, t_s=0.03)
        == "ServoJ(0.000000,0.000000,0.000000,0.000000,0.000000,0.000000,t=0.030000)"
    )
    assert dobot.digital_output(1, True) == "DO(1,1)"
    assert dobot.digital_output(2, False, tool=True) == "ToolDO(2,0)"
    assert dobot.emergency_stop(True) == "EmergencyStop(1)"
    assert dobot.inverse_kin([1, 2, 3, 4, 5, 6], [0] * 6).endswith(
        ",useJointNear=1,jointNear={0.000000,0.000000,0.000000,0.000000,0.000000,0.000000})"
    )
    with pytest.raises(ValueError):
        dobot.mov_j_joint([0] * 6, v=50.5)  # ratios are integers, as in the SDK
    with pytest.raises(ValueError):
        dobot.speed_factor(0)
