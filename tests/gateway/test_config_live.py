"""PUT /config reaches the running services over Zenoh, and a service that starts later catches up.

The gateway runs its own Zenoh session connected to the cell's (as `pickplace serve gateway` does);
the robot driver drives the simulated Dobot over its real TCP ports.
"""

from __future__ import annotations

import pytest
from pickplace.v1 import common_pb2

import gateway.app as gateway_app
from services.common.bus import Bus
from services.common.errors import InvalidInputError, LimitViolationError
from services.common.live_config import LiveConfig, settings_after
from services.motion.service import MotionPlannerServicer
from services.robot.service import RobotService
from tests.conftest import HOME, free_port
from tests.gateway.conftest import AUTH, gateway_settings, migrate_up, running_gateway, wait_until

pytestmark = pytest.mark.integration


async def test_put_config_applies_live_in_the_services(
    robot_settings, sim_server, sqlite_db, tmp_path, monkeypatch
):
    monkeypatch.setattr(gateway_app, "CONFIG_REPUBLISH_S", 0.3)
    await migrate_up(sqlite_db)
    cell = gateway_settings(robot_settings, sqlite_db, tmp_path)
    ratios = sim_server.controller.ratios
    async with Bus(cell.zenoh) as bus, RobotService(cell, bus, grpc_port=0) as robot:
        # the driver sends both ratios of the settings when it connects
        assert (ratios.speed_factor, ratios.acc_j, ratios.acc_l) == (50, 50, 50)
        motion = MotionPlannerServicer(cell)
        async with LiveConfig(bus, cell, motion.on_config):
            zs = cell.zenoh.model_copy(
                update={"listen": [f"tcp/127.0.0.1:{free_port()}"], "connect": cell.zenoh.listen}
            )
            gs = cell.model_copy(
                update={"zenoh": zs, "grpc": cell.grpc.model_copy(update={"robot_port": robot.grpc_port})}
            )
            async with running_gateway(gs) as gw:
                patch = {
                    "robot": {
                        "speed_ratio": 30,
                        "acc_ratio": 40,
                        "workspace": {"min": [-0.85, -0.85, 0.0], "max": [0.85, 0.85, 0.2]},
                    },
                    "motion": {"planner": "PRM", "velocity_scale": 0.5},
                }
                r = await gw.client.put("/api/v1/config", json=patch, headers=AUTH)
                assert r.status_code == 200, r.text
                assert set(r.json()["applied_now"]) == {
                    "robot.speed_ratio",
                    "robot.acc_ratio",
                    "robot.workspace.max",
                    "motion.planner",
                    "motion.velocity_scale",
                }
                await wait_until(
                    lambda: (ratios.speed_factor, ratios.acc_j, ratios.acc_l) == (30, 40, 40),
                    10.0,
                    "the controller's SpeedFactor/AccJ/AccL to follow PUT /config",
                )
                await wait_until(lambda: motion.motion.planner == "PRM", 10.0, "the motion service to follow")
                assert motion.motion.velocity_scale == 0.5 and robot.settings.robot.speed_ratio == 30
                # the smaller workspace guards the next command: a pose with the tool above 0.2 m is refused
                assert robot.driver.limits.workspace.max[2] == 0.2
                with pytest.raises(LimitViolationError, match="workspace"):
                    await robot.driver.move_joints(HOME)

                # a service (re)started after the PUT catches up from the gateway's republication
                late = LiveConfig(bus, cell)
                async with late:
                    await wait_until(
                        lambda: late.settings.robot.speed_ratio == 30, 10.0, "a late service to catch up"
                    )
                assert late.settings.motion.planner == "PRM" and late.updates_applied == 1

                # a bad value never leaves the gateway; the services keep what they have
                r = await gw.client.put("/api/v1/config", json={"robot": {"speed_ratio": 0}}, headers=AUTH)
                assert r.status_code == 422
                assert robot.settings.robot.speed_ratio == 30 and ratios.speed_factor == 30


async def test_a_follower_refuses_an_invalid_update_and_keeps_its_settings(settings):
    live = LiveConfig(None, settings)  # type: ignore[arg-type]  # apply() needs no bus
    bad = [
        ("{not json", "not JSON"),
        ('{"robot": {"speed_ratio": 500}}', "speed_ratio"),
        ('{"gateway": {"api_token": "x"}}', "cannot be changed"),
    ]
    for payload, words in bad:
        with pytest.raises(InvalidInputError, match=words):
            settings_after(settings, payload)
        assert await live.apply(common_pb2.ConfigUpdate(patch_json=payload)) == []
        assert live.settings is settings
    # the same cumulative patch twice: applied once
    good = common_pb2.ConfigUpdate(patch_json='{"vision": {"rate_hz": 2.0}}')
    assert await live.apply(good) == ["vision.rate_hz"]
    assert await live.apply(good) == []
    assert live.settings.vision.rate_hz == 2.0 and live.updates_applied == 1
    # a patch without a key it held before (a restarted gateway) puts that key back, and says so
    changed = await live.apply(common_pb2.ConfigUpdate(patch_json='{"robot": {"speed_ratio": 20}}'))
    assert sorted(changed) == ["robot.speed_ratio", "vision.rate_hz"]
    assert live.settings.vision.rate_hz == settings.vision.rate_hz and live.settings.robot.speed_ratio == 20
