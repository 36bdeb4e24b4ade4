"""Conversions between the driver's state and the protobuf messages of proto/ (pure)."""

from __future__ import annotations

import time

from pickplace.v1 import common_pb2, robot_pb2

from services.common.messages import matrix_to_pose
from services.dobot import RobotMode
from services.kinematics.robot_models import RobotSpec
from services.robot.feedback import FeedbackState


def joint_state_msg(fb: FeedbackState, spec: RobotSpec, seq: int = 0) -> common_pb2.JointState:
    return common_pb2.JointState(
        header=common_pb2.Header(stamp_ns=time.time_ns(), frame_id="base", seq=seq),
        name=list(spec.joint_names),
        position=fb.q.tolist(),
        velocity=fb.qd.tolist(),
        robot_mode=fb.robot_mode,
        current_command_id=fb.current_command_id,
        tcp_pose=matrix_to_pose(fb.T_base_tool),
        digital_outputs=fb.digital_outputs,
        digital_inputs=fb.digital_inputs,
        tcp_force=fb.tcp_force.tolist(),
        source_stamp_ns=fb.timestamp_ms * 1_000_000,
    )


def robot_status_msg(
    fb: FeedbackState | None, spec: RobotSpec, connected: bool, alarms: list[int], gripper_closed: bool
) -> robot_pb2.RobotStatus:
    status = robot_pb2.RobotStatus(
        connected=connected, robot_model=spec.name, gripper_closed=gripper_closed, alarms=alarms
    )
    if fb is not None:
        status.robot_mode = fb.robot_mode
        status.robot_mode_name = RobotMode.name_of(fb.robot_mode)
        status.enabled = fb.enabled
        status.estop_active = fb.estop
        status.joint_state.CopyFrom(joint_state_msg(fb, spec))
    return status
