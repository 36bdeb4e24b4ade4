"""The dashboard line protocol and the script-port program framer."""

from __future__ import annotations

from services.rtde.dashboard import DashboardCommand, LineFramer, parse_line
from services.rtde.script import ScriptFramer


def test_dashboard_lines_are_commands_case_insensitive_with_arguments() -> None:
    assert parse_line("PolyscopeVersion").command is DashboardCommand.POLYSCOPE_VERSION
    assert parse_line("unlock protective stop").command is DashboardCommand.UNLOCK_PROTECTIVE_STOP
    req = parse_line("addToLog hello world")
    assert req.command is DashboardCommand.ADD_TO_LOG and req.argument == "hello world"
    assert parse_line("jump around").command is None


def test_dashboard_framer_splits_lines_and_keeps_a_partial_one() -> None:
    f = LineFramer()
    assert list(f.feed(b"robotmode\r\npower o")) == ["robotmode"]
    assert list(f.feed(b"n\n")) == ["power on"]


def test_a_program_ends_at_its_column_zero_end_and_carries_ur_rtdes_offsets() -> None:
    text = (
        "def rtde_control():\n"
        "    global reg_offset_float = # float register offset\n24\n"
        "    global reg_offset_int = # int register offset\n24\n"
        "    def f():\n        textmsg(1)\n    end\n"
        "end\n"
    )
    f = ScriptFramer()
    assert list(f.feed(text[:40].encode())) == []
    (program,) = list(f.feed(text[40:].encode()))
    assert program.name == "rtde_control" and program.is_rtde_control and not program.secondary
    assert program.register_offsets == (24, 24)
    assert program.text.endswith("    end\nend\n")


def test_a_lone_line_is_a_secondary_command() -> None:
    (cmd,) = list(ScriptFramer().feed(b"set_digital_out(0, True)\n"))
    assert cmd.secondary and cmd.name == ""
