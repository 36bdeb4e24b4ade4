"""RTDE field types and the variables this codec knows (name → type), from UR's RTDE guide.

A controller answers a recipe with one type name per variable (``NOT_FOUND`` for an unknown output,
``IN_USE`` for an input another client already writes). ur_rtde decodes data by its own table
(``src/robot_state.cpp``), so the types here must agree with it for every variable it reads.
"""

from __future__ import annotations

import enum
import re
import struct


class FieldType(enum.Enum):
    BOOL = "BOOL"
    UINT8 = "UINT8"
    UINT32 = "UINT32"
    UINT64 = "UINT64"
    INT32 = "INT32"
    DOUBLE = "DOUBLE"
    VECTOR3D = "VECTOR3D"
    VECTOR6D = "VECTOR6D"
    VECTOR6INT32 = "VECTOR6INT32"
    VECTOR6UINT32 = "VECTOR6UINT32"

    @property
    def struct_format(self) -> str:
        """Big-endian struct format of one value (network order, as every RTDE number)."""
        return _FORMATS[self]

    @property
    def size(self) -> int:
        return struct.calcsize(">" + _FORMATS[self])

    @property
    def count(self) -> int:
        """Numbers in one value (1 for scalars)."""
        return len(_FORMATS[self])


_FORMATS = {
    FieldType.BOOL: "?",
    FieldType.UINT8: "B",
    FieldType.UINT32: "I",
    FieldType.UINT64: "Q",
    FieldType.INT32: "i",
    FieldType.DOUBLE: "d",
    FieldType.VECTOR3D: "ddd",
    FieldType.VECTOR6D: "dddddd",
    FieldType.VECTOR6INT32: "iiiiii",
    FieldType.VECTOR6UINT32: "IIIIII",
}

T = FieldType
OUTPUTS: dict[str, FieldType] = {
    "timestamp": T.DOUBLE,
    "target_q": T.VECTOR6D,
    "target_qd": T.VECTOR6D,
    "target_qdd": T.VECTOR6D,
    "target_current": T.VECTOR6D,
    "target_moment": T.VECTOR6D,
    "actual_q": T.VECTOR6D,
    "actual_qd": T.VECTOR6D,
    "actual_current": T.VECTOR6D,
    "joint_control_output": T.VECTOR6D,
    "actual_TCP_pose": T.VECTOR6D,
    "actual_TCP_speed": T.VECTOR6D,
    "actual_TCP_force": T.VECTOR6D,
    "target_TCP_pose": T.VECTOR6D,
    "target_TCP_speed": T.VECTOR6D,
    "actual_digital_input_bits": T.UINT64,
    "joint_temperatures": T.VECTOR6D,
    "actual_execution_time": T.DOUBLE,
    "robot_mode": T.INT32,
    "joint_mode": T.VECTOR6INT32,
    "safety_mode": T.INT32,
    "safety_status": T.INT32,
    "actual_tool_accelerometer": T.VECTOR3D,
    "speed_scaling": T.DOUBLE,
    "target_speed_fraction": T.DOUBLE,
    "actual_momentum": T.DOUBLE,
    "actual_main_voltage": T.DOUBLE,
    "actual_robot_voltage": T.DOUBLE,
    "actual_robot_current": T.DOUBLE,
    "actual_joint_voltage": T.VECTOR6D,
    "actual_digital_output_bits": T.UINT64,
    "runtime_state": T.UINT32,
    "robot_status_bits": T.UINT32,
    "safety_status_bits": T.UINT32,
    "standard_analog_input0": T.DOUBLE,
    "standard_analog_input1": T.DOUBLE,
    "standard_analog_output0": T.DOUBLE,
    "standard_analog_output1": T.DOUBLE,
    "ft_raw_wrench": T.VECTOR6D,
    "payload": T.DOUBLE,
    "payload_cog": T.VECTOR3D,
    "payload_inertia": T.VECTOR6D,
    "elbow_position": T.VECTOR3D,
    "elbow_velocity": T.VECTOR3D,
    "output_bit_registers0_to_31": T.UINT32,
    "output_bit_registers32_to_63": T.UINT32,
}

INPUTS: dict[str, FieldType] = {
    "speed_slider_mask": T.UINT32,
    "speed_slider_fraction": T.DOUBLE,
    "standard_digital_output_mask": T.UINT8,
    "standard_digital_output": T.UINT8,
    "configurable_digital_output_mask": T.UINT8,
    "configurable_digital_output": T.UINT8,
    "tool_digital_output_mask": T.UINT8,
    "tool_digital_output": T.UINT8,
    "standard_analog_output_mask": T.UINT8,
    "standard_analog_output_type": T.UINT8,
    "standard_analog_output_0": T.DOUBLE,
    "standard_analog_output_1": T.DOUBLE,
    "external_force_torque": T.VECTOR6D,
    "input_bit_registers0_to_31": T.UINT32,
    "input_bit_registers32_to_63": T.UINT32,
}

REGISTERS = 48  # general purpose registers 0..47 (24..47 are the "upper range")
_REGISTER = re.compile(r"^(input|output)_(int|double)_register_(\d+)$")


def register(name: str) -> tuple[str, str, int] | None:
    """``("input", "int", 3)`` for ``input_int_register_3``; None for any other name or index."""
    m = _REGISTER.match(name)
    if m is None or int(m.group(3)) >= REGISTERS:
        return None
    return m.group(1), m.group(2), int(m.group(3))


def output_type(name: str) -> FieldType | None:
    """The type of an output variable (None: ``NOT_FOUND``). Input registers can be read back too."""
    reg = register(name)
    if reg is not None:
        return T.INT32 if reg[1] == "int" else T.DOUBLE
    return OUTPUTS.get(name)


def input_type(name: str) -> FieldType | None:
    """The type of an input variable a client may write (None: ``NOT_FOUND``)."""
    reg = register(name)
    if reg is not None:
        if reg[0] != "input":
            return None
        return T.INT32 if reg[1] == "int" else T.DOUBLE
    return INPUTS.get(name)
