import os
from pathlib import Path

import pytest

from services.common.errors import ConfigurationError
from services.common.settings import CONFIG_DIR, load_settings


def test_default_sim_profile_is_loopback():
    s = load_settings("sim")
    assert s.robot.host == "127.0.0.1"
    assert s.zenoh.multicast_scouting is False
    assert all("127.0.0.1" in ep for ep in s.zenoh.listen)
    assert s.grpc.host == "127.0.0.1"


def test_real_profile_carries_the_robot_address():
    s = load_settings("nova5-real")
    assert s.robot.allow_remote is True
    assert not s.robot.host.startswith("127.")


def test_env_override_nested(monkeypatch):
    monkeypatch.setenv("PICKPLACE_ROBOT__SPEED_RATIO", "30")
    monkeypatch.setenv("PICKPLACE_CELL_ID", "cellA")
    s = load_settings("sim")
    assert s.robot.speed_ratio == 30
    assert s.cell_id == "cellA"


@pytest.mark.parametrize("ratio", ["0", "101", "150"])
def test_unsafe_speed_ratio_rejected(monkeypatch, ratio):
    monkeypatch.setenv("PICKPLACE_ROBOT__SPEED_RATIO", ratio)
    with pytest.raises(ConfigurationError, match="speed_ratio"):
        load_settings("sim")


def test_robot_address_in_sim_profile_rejected():
    # even with allow_remote the sim profile must not name a robot address
    with pytest.raises(ConfigurationError, match="sim profile"):
        load_settings("sim", overrides={"robot": {"host": "203.0.113.7", "allow_remote": True}})


def test_non_loopback_robot_needs_explicit_allow():
    with pytest.raises(ConfigurationError, match="not a loopback"):
        load_settings("nova5-real", overrides={"robot": {"allow_remote": False}})


def test_zenoh_multicast_and_remote_endpoints_rejected():
    with pytest.raises(ConfigurationError, match="multicast"):
        load_settings("sim", overrides={"zenoh": {"multicast_scouting": True}})
    with pytest.raises(ConfigurationError, match="not loopback"):
        load_settings("sim", overrides={"zenoh": {"connect": ["tcp/203.0.113.5:7447"]}})


def test_unknown_profile_and_bad_yaml(tmp_path: Path):
    with pytest.raises(ConfigurationError, match="unknown profile"):
        load_settings("nope")
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: [unclosed")
    with pytest.raises(ConfigurationError, match="not valid YAML"):
        load_settings("sim", config_file=bad)


def test_unknown_key_rejected(tmp_path: Path):
    extra = tmp_path / "x.yaml"
    extra.write_text("robot:\n  sped_ratio: 20\n")
    with pytest.raises(ConfigurationError, match="sped_ratio"):
        load_settings("sim", config_file=extra)


def test_only_the_real_profile_names_the_robot_address():
    hits = [p.name for p in (CONFIG_DIR / "profiles").glob("*.yaml") if "192.168." in p.read_text()]
    assert hits == ["nova5-real.yaml"]
    assert "192.168." not in (CONFIG_DIR / "default.yaml").read_text()
    assert os.environ.get("PICKPLACE_ROBOT__HOST") is None


def test_the_rod_place_must_lie_in_its_region():
    with pytest.raises(ConfigurationError, match=r"place_xy_m \(0\.7, 0\.0\) lies outside the place region"):
        load_settings("sim", overrides={"grasp": {"rod": {"place_xy_m": [0.7, 0.0]}}})
    with pytest.raises(ConfigurationError, match="must lie below"):
        load_settings("sim", overrides={"grasp": {"rod": {"place_region_min_m": [0.6, -0.25]}}})
    moved = {"place_xy_m": [0.25, 0.35], "place_region_min_m": [0.2, 0.3], "place_region_max_m": [0.3, 0.4]}
    assert load_settings("sim", overrides={"grasp": {"rod": moved}}).grasp.rod.place_xy_m == (0.25, 0.35)
