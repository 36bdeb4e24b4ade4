"""The cycle's configuration as the runner builds it from the settings."""

from __future__ import annotations

from services.common.settings import load_settings
from services.task.runner import cycle_config


def test_the_rod_is_stood_where_the_settings_say() -> None:
    # the task used to stand it at its own default (0.45, 0) whatever grasp.rod.place_xy_m said
    moved = {"place_xy_m": [0.25, 0.35], "place_region_min_m": [0.2, 0.3], "place_region_max_m": [0.3, 0.4]}
    cfg = cycle_config(load_settings("sim", overrides={"grasp": {"rod": moved}}))
    assert cfg.place_xy == (0.25, 0.35)
    assert cfg.place_region_min == (0.2, 0.3) and cfg.place_region_max == (0.3, 0.4)
    where_it_lay = cycle_config(load_settings("sim", overrides={"grasp": {"rod": {"place_xy_m": None}}}))
    assert where_it_lay.place_xy is None  # the grasp service stands it where it lay
