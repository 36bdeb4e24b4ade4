"""End to end in headless Chromium (Debian's /usr/bin/chromium, driven by Playwright).

The real robot-driver service and the simulated Dobot feed the dashboard; a scripted task
service answers Start. The test loads the dashboard, sees live joint states, presses Start and
sees the pick appear in the history, presses E-stop while the arm moves and sees the state
change and the arm stop. A screenshot is saved to ``artifacts/dashboard.png``.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import cv2
import numpy as np
import pytest
from pickplace.v1 import vision_pb2

from services.common.bus import Bus
from services.common.keys import CellKeys
from services.common.modes import TaskKind
from services.common.settings import REPO_ROOT
from services.robot.service import RobotService
from tests.gateway.conftest import (
    TOKEN,
    fake_task_service,
    gateway_settings,
    migrate_up,
    running_gateway,
    wait_until,
)

pytestmark = [pytest.mark.integration, pytest.mark.slow]

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_INSTALLED = CHROMIUM.exists()
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--enable-unsafe-swiftshader",  # software WebGL for the 3D view
]
ARTIFACTS = REPO_ROOT / "artifacts"


def camera_jpeg() -> bytes:
    """A stand-in for the vision debug image: a table with a rod and a labelled box drawn on it."""
    img = np.full((480, 640, 3), (60, 70, 80), np.uint8)
    cv2.rectangle(img, (0, 260), (640, 480), (150, 150, 140), -1)
    cv2.line(img, (250, 330), (400, 350), (20, 20, 20), 12)
    cv2.rectangle(img, (240, 315), (410, 365), (0, 255, 0), 2)
    cv2.putText(img, "rod 0.93", (240, 305), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 255, 0), 2)
    ok, buf = cv2.imencode(".jpg", img)
    assert ok
    return buf.tobytes()


async def test_dashboard_live_start_pick_and_estop(robot_settings, sim_server, sqlite_db, tmp_path):
    from playwright.async_api import async_playwright, expect

    assert CHROMIUM_INSTALLED, (
        "Debian's chromium is missing: `make install` installs it (apt-get install chromium)"
    )
    await migrate_up(sqlite_db)
    s = gateway_settings(robot_settings, sqlite_db, tmp_path)
    async with Bus(s.zenoh) as bus, RobotService(s, bus, grpc_port=0) as robot:
        await robot.driver.enable()
        s = s.model_copy(update={"grpc": s.grpc.model_copy(update={"robot_port": robot.grpc_port})})
        async with (
            fake_task_service(bus, s.cell_id, s.grpc.task_port) as task,
            running_gateway(s, bus) as gw,
            async_playwright() as pw,
        ):
            browser = await pw.chromium.launch(
                executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
            )
            try:
                page = await browser.new_page(viewport={"width": 1280, "height": 800})
                errors: list[str] = []
                page.on("pageerror", lambda exc: errors.append(str(exc)))
                await page.goto(f"{gw.server.url}/#token={TOKEN}")

                # live joint states from the real driver: the sim starts at home (joint 3 at 90 deg)
                await expect(page.get_by_test_id("joint-3")).to_have_text("90.00", timeout=15_000)
                await expect(page.get_by_test_id("robot-mode")).to_have_text("ENABLE", timeout=10_000)
                await expect(page.locator("#robot3d")).to_have_attribute(
                    "data-loaded", "true", timeout=15_000
                )

                # the vision service's debug image appears in the camera panel
                bus.publish(CellKeys(s.cell_id).vision_debug_image, vision_pb2.DebugImage(jpeg=camera_jpeg()))
                await expect(page.locator("#camera-img")).to_be_visible(timeout=10_000)

                # Start → the task service runs one cycle → its pick shows up in the history
                await page.get_by_role("button", name="start the task").click()
                await expect(page.get_by_test_id("history").locator("tr.ok")).to_have_count(1, timeout=15_000)
                assert task.starts == [(TaskKind.STAND_ROD, 0)]
                await expect(page.get_by_test_id("success-rate")).to_have_text("100.0 %", timeout=10_000)

                # E-stop while the arm moves
                target = np.deg2rad([120.0, 0.0, 90.0, 0.0, -90.0, 0.0])
                move = asyncio.ensure_future(robot.driver.move_joints(target, speed_ratio=10))
                await robot.driver.client.wait_feedback(lambda fb: fb.q[0] > np.deg2rad(3), 5.0)
                await page.get_by_role("button", name="emergency stop").click()
                await wait_until(
                    lambda: sim_server.controller.estop, 5.0, "the simulated controller's e-stop"
                )
                await expect(page.get_by_test_id("robot-mode")).to_have_text("E-STOP", timeout=10_000)
                await expect(page.get_by_test_id("state")).to_have_text("ESTOP", timeout=10_000)
                with pytest.raises(Exception):  # noqa: B017 — the move is aborted by the e-stop
                    await move
                await wait_until(lambda: task.estops == 1, 5.0, "the task service to hear of the e-stop")

                q1 = robot.driver.client.feedback.q.copy()
                await asyncio.sleep(0.3)
                q2 = robot.driver.client.feedback.q.copy()
                assert q1[0] < np.deg2rad(119.0), "the arm reached its goal: the e-stop did not stop it"
                assert np.allclose(q1, q2, atol=1e-9), f"the arm still moves after the e-stop: {q1} → {q2}"

                # a status poll answered after the e-stop must not bring the old state back
                async with page.expect_response(lambda r: r.url.endswith("/api/v1/system/status")):
                    pass
                await expect(page.get_by_test_id("robot-mode")).to_have_text("E-STOP")
                await expect(page.get_by_test_id("state")).to_have_text("ESTOP")

                ARTIFACTS.mkdir(exist_ok=True)
                await page.screenshot(path=str(ARTIFACTS / "dashboard.png"))
                assert not errors, f"JavaScript errors on the page: {errors}"
            finally:
                await browser.close()
