"""End to end in headless Chromium (Debian's /usr/bin/chromium, driven by Playwright).

The real robot-driver service and the simulated Dobot feed the dashboard; a scripted task
service answers Start. The test loads the dashboard, sees live joint states, the camera's frustum
and the planned path in the 3D view (``artifacts/robot3d-frustum-plan.png``), presses Start and
sees the pick appear in the history, presses E-stop while the arm moves and sees the state
change and the arm stop. A screenshot is saved to ``artifacts/dashboard.png``.
"""

from __future__ import annotations

import asyncio
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from pickplace.v1 import task_pb2, vision_pb2

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


def rgbd_frame(w: int = 640, h: int = 480) -> vision_pb2.RGBDFrame:
    """A camera frame for its pinhole (the D435i's at 640×480); the pixels do not matter here."""
    return vision_pb2.RGBDFrame(
        intrinsics=vision_pb2.CameraIntrinsics(width=w, height=h, fx=615.0, fy=615.0, cx=320.0, cy=240.0),
        color_rgb8=bytes(w * h * 3),
        depth_u16=bytes(w * h * 2),
        depth_scale=0.001,
    )


def task_plan(cycle: int, seq: int, label: str, n: int) -> task_pb2.TaskPlan:
    """A plan as the task publishes it: the tool tip's path, here an arc from above the rod to above the table."""
    s = np.linspace(0.0, 1.0, n)
    plan = task_pb2.TaskPlan(cycle_index=cycle, label=label)
    plan.header.seq = seq
    for x, y, z in zip(0.45 + 0.1 * s, -0.2 + 0.4 * s, 0.05 + 0.25 * np.sin(np.pi * s), strict=True):
        plan.tool_path.add(x=float(x), y=float(y), z=float(z))
    return plan


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
                keys = CellKeys(s.cell_id)
                bus.publish(keys.vision_debug_image, vision_pb2.DebugImage(jpeg=camera_jpeg()))
                await expect(page.locator("#camera-img")).to_be_visible(timeout=10_000)

                # the 3D view: the camera's frustum (a frame's pinhole, the calibrated pose) and the
                # current cycle's planned path (the task's plans on the bus; a new cycle starts afresh)
                view3d = page.locator("#robot3d")
                bus.publish(keys.camera_frames, rgbd_frame())
                bus.publish(keys.vision_debug_image, vision_pb2.DebugImage(jpeg=camera_jpeg()))
                await expect(view3d).to_have_attribute("data-frustum", "true", timeout=15_000)
                bus.publish(keys.task_plans, task_plan(3, 1, "APPROACH+GRASP", 20))
                bus.publish(keys.task_plans, task_plan(3, 2, "LIFT+PLACE", 30))
                await expect(view3d).to_have_attribute("data-plan-points", "50", timeout=10_000)
                await expect(view3d).to_have_attribute("data-plan-cycle", "3")
                ARTIFACTS.mkdir(exist_ok=True)
                await view3d.screenshot(path=str(ARTIFACTS / "robot3d-frustum-plan.png"))
                bus.publish(keys.task_plans, task_plan(4, 3, "APPROACH", 12))
                await expect(view3d).to_have_attribute("data-plan-points", "12", timeout=10_000)
                await expect(view3d).to_have_attribute("data-plan-cycle", "4")

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

                # at rest: the same joints 0.3 s later on the controller's clock
                fb1 = robot.driver.client.feedback
                q1 = fb1.q.copy()
                fb2 = await robot.driver.client.wait_feedback(
                    lambda fb: fb.timestamp_ms >= fb1.timestamp_ms + 300, 10.0
                )
                q2 = fb2.q.copy()
                assert q1[0] < np.deg2rad(119.0), "the arm reached its goal: the e-stop did not stop it"
                assert np.allclose(q1, q2, atol=1e-9), f"the arm still moves after the e-stop: {q1} → {q2}"

                # a status poll answered after the e-stop must not bring the old state back
                async with page.expect_response(lambda r: r.url.endswith("/api/v1/system/status")):
                    pass
                await expect(page.get_by_test_id("robot-mode")).to_have_text("E-STOP")
                await expect(page.get_by_test_id("state")).to_have_text("ESTOP")

                ARTIFACTS.mkdir(exist_ok=True)
                await page.screenshot(path=str(ARTIFACTS / "dashboard.png"))

                # a dashboard opened now shows what went before: the gateway's timeline, replayed
                late = await browser.new_page(viewport={"width": 1280, "height": 800})
                late.on("pageerror", lambda exc: errors.append(str(exc)))
                await late.goto(f"{gw.server.url}/")
                timeline = late.get_by_test_id("events")
                await expect(timeline).to_have_attribute(
                    "data-replayed", re.compile(r"^[1-9]\d*$"), timeout=15_000
                )
                await expect(timeline).to_contain_text("E-STOP pressed")
                await expect(timeline).to_contain_text("E-STOP active on the robot")
                assert not errors, f"JavaScript errors on the page: {errors}"
            finally:
                await browser.close()
