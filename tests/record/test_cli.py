"""The command line of the live view and the recorder: options, the layout file, replay's bad input."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from services.apps.cli import app
from services.apps.record_cli import record_overrides
from services.common.settings import REPO_ROOT, load_settings
from services.record.channels import Topic

LAYOUT = REPO_ROOT / "deploy" / "foxglove" / "pickplace-layout.json"


def test_up_and_serve_options_become_the_record_settings(tmp_path: Path) -> None:
    assert record_overrides(None, False, None) == {}
    over = record_overrides(9001, True, str(tmp_path / "rec"))
    s = load_settings("sim", overrides={"record": over})
    assert (s.record.foxglove.port, s.record.foxglove.enabled, s.record.dir) == (
        9001,
        False,
        str(tmp_path / "rec"),
    )
    for command in ("up", "serve"):
        out = CliRunner().invoke(app, [command, "--help"]).output
        assert "--foxglove-port" in out and "--no-foxglove" in out and "--record" in out, command


def test_replay_of_a_file_that_is_no_recording_names_it_and_exits_2(tmp_path: Path) -> None:
    bad = tmp_path / "holiday.mcap"
    bad.write_bytes(b"GIF89a not a recording")
    result = CliRunner().invoke(app, ["replay", str(bad), "--no-foxglove"])
    assert result.exit_code == 2
    assert "holiday.mcap is not an MCAP file" in result.output.replace("\n", "")


def test_the_layout_shows_channels_the_cell_publishes() -> None:
    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    topics = set(map(str, Topic))
    used = {
        panels["Image!camera"]["imageMode"]["imageTopic"],
        panels["Image!camera"]["imageMode"]["calibrationTopic"],
        panels["3D!cell"]["layers"]["robot"]["topic"],
        panels["RosOut!log"]["topicToRender"],
        *(p["value"].split(".")[0] for p in panels["Plot!joints"]["paths"]),
        *(v["topicPath"] for k, v in panels.items() if k.startswith("RawMessages!")),
        *panels["3D!cell"]["topics"],
    }
    assert used <= topics, used - topics
    assert {"3D!cell", "Image!camera", "Plot!joints", "RosOut!log"} <= set(panels)
