"""The RTDE codec on byte fixtures: headers, partial packages, recipes, setup replies."""

from __future__ import annotations

import struct

import pytest

from services.rtde import codec
from services.rtde.codes import MessageType
from services.rtde.fields import FieldType, input_type, output_type


def test_a_package_is_size_type_payload_big_endian() -> None:
    assert codec.request_protocol_version() == b"\x00\x05V\x00\x02"  # what ur_rtde 1.6.5 sends
    assert codec.protocol_version_reply(True) == b"\x00\x04V\x01"
    assert codec.controller_version_reply((5, 11, 1, 108318)) == (
        b"\x00\x13v" + struct.pack(">IIII", 5, 11, 1, 108318)
    )


def test_the_framer_waits_for_whole_packages_and_splits_joined_ones() -> None:
    stream = codec.start_pause_reply(MessageType.CONTROL_PACKAGE_START, True) + codec.setup_inputs_request(
        ["input_int_register_0", "input_double_register_0"]
    )
    f = codec.Framer()
    assert list(f.feed(stream[:2])) == []  # part of a header: wait
    pkgs = list(f.feed(stream[2:7]))  # the first package, and a header without its payload
    assert len(pkgs) == 1
    pkgs += list(f.feed(stream[7:]))
    assert [p.type for p in pkgs] == [
        MessageType.CONTROL_PACKAGE_START,
        MessageType.CONTROL_PACKAGE_SETUP_INPUTS,
    ]
    assert pkgs[0].payload == b"\x01"
    assert codec.split_names(pkgs[1].payload) == ("input_int_register_0", "input_double_register_0")


def test_a_header_shorter_than_itself_is_a_protocol_error() -> None:
    with pytest.raises(codec.RTDEProtocolError, match="less than its own 3"):
        list(codec.Framer().feed(b"\x00\x02U"))


def test_output_setup_carries_the_frequency_then_names_with_ur_rtdes_trailing_comma() -> None:
    payload = struct.pack(">d", 500.0) + b"timestamp,actual_q,robot_mode,"
    assert codec.parse_setup_outputs(payload) == (500.0, ("timestamp", "actual_q", "robot_mode"))


def test_a_recipe_packs_and_unpacks_every_field_type_in_order() -> None:
    names = (
        "timestamp",
        "actual_q",
        "robot_mode",
        "runtime_state",
        "actual_digital_output_bits",
        "joint_mode",
    )
    types = tuple(output_type(n) for n in names)
    assert types == (
        FieldType.DOUBLE,
        FieldType.VECTOR6D,
        FieldType.INT32,
        FieldType.UINT32,
        FieldType.UINT64,
        FieldType.VECTOR6INT32,
    )
    recipe = codec.Recipe(1, names, types)  # type: ignore[arg-type]
    values = {
        "timestamp": 12.344,
        "actual_q": (0.1, -1.2, 1.3, -1.4, -1.5, 0.6),
        "robot_mode": -1,
        "runtime_state": 2,
        "actual_digital_output_bits": 1 << 16,
        "joint_mode": (253,) * 6,
    }
    payload = recipe.pack(values)
    assert payload[0] == 1 and len(payload) == 1 + 8 + 48 + 4 + 4 + 8 + 24
    assert payload[1:9] == struct.pack(">d", 12.344)
    assert recipe.unpack(payload) == values


def test_a_data_package_that_does_not_fit_its_recipe_is_refused_by_name() -> None:
    recipe = codec.Recipe(
        3, ("input_int_register_0", "input_double_register_0"), (FieldType.INT32, FieldType.DOUBLE)
    )
    with pytest.raises(codec.RTDEProtocolError, match="recipe 3 data is 4 bytes"):
        recipe.unpack(b"\x03" + struct.pack(">i", 1))
    with pytest.raises(codec.RTDEProtocolError, match="needs 6 values"):
        codec.Recipe(1, ("actual_q",), (FieldType.VECTOR6D,)).pack({"actual_q": (1.0, 2.0)})


def test_registers_and_io_fields_have_types_and_unknown_names_none() -> None:
    assert input_type("input_int_register_23") is FieldType.INT32
    assert input_type("input_double_register_47") is FieldType.DOUBLE
    assert input_type("tool_digital_output_mask") is FieldType.UINT8
    assert input_type("output_int_register_0") is None  # outputs are not written by clients
    assert input_type("input_int_register_48") is None
    assert output_type("output_int_register_2") is FieldType.INT32
    assert output_type("no_such_variable") is None


def test_setup_replies_carry_the_recipe_id_then_type_words() -> None:
    reply = codec.setup_reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS, 4, ["INT32", "IN_USE"])
    pkg = next(codec.Framer().feed(reply))
    assert codec.parse_setup_reply(pkg.payload) == (4, ("INT32", "IN_USE"))
