"""The operator's panel on `pickplace up` itself (``run_pick_cell``: every service, the twin, the embedded
gateway), in Debian's headless Chromium. The cell starts picking; the test watches a real pick reach the
history, the trend and the stage bars; reads every panel (camera views and detections, robot facts,
events); checks every Grafana query finds its series in the cell's /metrics; changes the speed ratio;
then Stop, E-STOP (the alarm with its meaning in the timeline), Reset and Start — and the cell is still
up and picking. The link drops (browser offline) and the panel greys out "stale since", then recovers.
Screenshots of each step are kept in ``artifacts/``.
"""

from __future__ import annotations

import asyncio
import io
import re

import httpx
import pytest
from rich.console import Console

from services.apps.cell import Cell
from services.apps.up import run_pick_cell
from tests.apps.conftest import cell_settings
from tests.gateway.dashboard_queries import empty_selectors
from tests.gateway.test_browser import ARTIFACTS, CHROMIUM, CHROMIUM_ARGS, CHROMIUM_INSTALLED

# a loaded machine runs the cell at half speed and some cycles fail: the waits for a pick are safety nets
pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(900)]

RUNNING_STATE = re.compile(r"^(INIT|DETECT|PLAN|APPROACH|GRASP|LIFT|REORIENT|PLACE|RELEASE|DONE|RETRY)$")


# uvicorn closes a connection idle for 5 s: a request sent on it as it closes gets no answer (seen beside
# a loaded machine: GET /metrics after the e-stop steps). The client drops its idle ones well before.
KEEP_ALIVE_BELOW_THE_SERVERS = httpx.Limits(keepalive_expiry=2.0)


async def expect_success_rate_of_api(shown, api: httpx.AsyncClient) -> None:  # type: ignore[no-untyped-def]
    """The panel shows GET /metrics' success rate (above 0: a pick succeeded). Read again if a pick
    finishing meanwhile changed it (at most twice)."""
    from playwright.async_api import expect

    for attempt in range(3):
        rate = (await api.get("/api/v1/metrics")).json()["success_rate"]
        assert rate is not None and rate > 0, rate
        try:
            await expect(shown).to_have_text(f"{100 * rate:.1f} %", timeout=10_000)
            return
        except AssertionError:
            if attempt == 2:
                raise


async def test_operator_panel_on_pickplace_up(tmp_path):
    from playwright.async_api import async_playwright, expect

    assert CHROMIUM_INSTALLED, (
        "Debian's chromium is missing: `make install` installs it (apt-get install chromium)"
    )
    s = cell_settings(
        tmp_path,
        gateway={"port": 0, "edge_grpc_port": 0},
        database={"url": f"sqlite+aiosqlite:///{tmp_path / 'cell.db'}"},
    )
    ready: asyncio.Future[tuple[Cell, str]] = asyncio.get_running_loop().create_future()
    run = asyncio.create_task(
        run_pick_cell(s, 0, Console(file=io.StringIO(), width=120), lambda c, u: ready.set_result((c, u)))
    )
    ARTIFACTS.mkdir(exist_ok=True)
    try:
        async with asyncio.timeout(60):
            _cell, url = await ready
        base, token = url.split("/#token=")
        async with (
            async_playwright() as pw,
            httpx.AsyncClient(base_url=base, timeout=30, limits=KEEP_ALIVE_BELOW_THE_SERVERS) as api,
        ):
            browser = await pw.chromium.launch(
                executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
            )
            try:
                context = await browser.new_context(viewport={"width": 1600, "height": 1000})
                page = await context.new_page()
                errors: list[str] = []
                page.on("pageerror", lambda exc: errors.append(str(exc)))
                await page.goto(url)
                tid = page.get_by_test_id

                # live: the task runs at once (pickplace up starts it); header and task panel agree
                await expect(tid("state")).to_have_text(RUNNING_STATE, timeout=30_000)
                await expect(tid("state")).to_have_class("ok")
                await expect(tid("task")).to_contain_text("running")
                await expect(tid("robot-mode")).to_have_class(re.compile(r"\bok\b"), timeout=10_000)
                await expect(page.locator("#camera-img")).to_be_visible(timeout=30_000)
                # the detection list: each object with its confidence (rods) or fit (cubes), as vision sees it
                found = tid("detections").locator("tr.rod, tr.cube, tr.obstacle")
                await expect(found.first).to_be_visible(timeout=30_000)
                await expect(found.first.locator("td.conf")).to_have_text(
                    re.compile(r"\d+ %|fit \d|recognised|unknown")
                )
                # the 3D view shows what vision sees and where the task places things
                view3d = page.locator("#robot3d")
                await expect(view3d).to_have_attribute("data-loaded", "true", timeout=30_000)
                await expect(view3d).to_have_attribute(
                    "data-objects", re.compile(r"^[1-9]\d*$"), timeout=20_000
                )
                await expect(view3d).to_have_attribute("data-targets", re.compile(r"^[1-9]\d*$"))
                # the camera's frustum, from the calibration file and the camera's pinhole
                await expect(view3d).to_have_attribute("data-frustum", "true", timeout=20_000)
                await expect(tid("tcp-pose")).to_have_text(re.compile(r"-?\d+\.\d .*"), timeout=10_000)
                await expect(tid("wrist-force")).to_have_text(re.compile(r"\d+\.\d"))
                await expect(tid("gripper")).to_have_text(re.compile(r"^(open|closed)$"))

                # one real pick-and-stand: history, statistics, trend and stage bars
                # (on a loaded machine a cycle may fail before or after it: every check allows for that)
                await expect(tid("history").locator("tr.ok")).to_have_count(1, timeout=420_000)
                await expect_success_rate_of_api(tid("success-rate"), api)
                await expect(tid("cycle-trend")).to_have_attribute(
                    "data-points", re.compile(r"^[1-9]\d*$"), timeout=10_000
                )
                await expect(tid("stage-bars")).to_have_attribute(
                    "data-bars", re.compile(r"^[1-9]\d*$"), timeout=10_000
                )
                await page.screenshot(path=str(ARTIFACTS / "panel-picking.png"))
                # the planned path of the current cycle (the task's plans on the bus)
                await expect(view3d).to_have_attribute("data-plan-points", re.compile(r"^[1-9]\d*$"))
                await expect(view3d).to_have_attribute("data-plan-cycle", re.compile(r"^\d+$"))
                await view3d.screenshot(path=str(ARTIFACTS / "panel-3d.png"))

                # camera: depth view, enlarged
                await page.get_by_role("radio", name="depth").check()
                await expect(page.locator("#camera-img")).to_have_attribute(
                    "data-view", "depth", timeout=10_000
                )
                await tid("camera").click()
                await expect(tid("camera")).to_have_class(re.compile("enlarged"))
                await page.screenshot(path=str(ARTIFACTS / "panel-camera-depth.png"))
                await tid("camera").click()
                await page.get_by_role("radio", name="overlay").check()

                # calibration needs the arm: refused (409) while the task runs
                auth = {"Authorization": f"Bearer {token}"}
                r = await api.post("/api/v1/calibration/handshake", json={"num_poses": 6}, headers=auth)
                assert r.status_code == 409 and "stop the task" in r.json()["detail"], r.text

                # speed ratio through PUT /config
                await page.locator("#speed-range").fill("35")
                # the output shows what the slider says at once: the PUT's answer is the event to wait for
                async with page.expect_response(
                    lambda r: r.url.endswith("/api/v1/config") and r.request.method == "PUT", timeout=30_000
                ) as put:
                    await page.get_by_role("button", name="apply the speed ratio").click()
                assert (await put.value).ok
                await expect(tid("speed-ratio")).to_have_text("35 %")
                assert (await api.get("/api/v1/config")).json()["robot"]["speed_ratio"] == 35

                # Stop: header and task panel say the same; the cell stays up
                await page.get_by_role("button", name="stop the task").click()
                await expect(tid("state")).to_have_text(re.compile(r"^(STOPPED|IDLE)$"), timeout=60_000)
                await expect(tid("task")).to_contain_text("idle")
                assert not run.done()

                # E-STOP: flashing state, the Dobot alarm with its meaning in the timeline
                await page.get_by_role("button", name="emergency stop").click()
                await expect(tid("state")).to_have_text("ESTOP", timeout=10_000)
                await expect(tid("state")).to_have_class("estop")
                await expect(tid("robot-mode")).to_have_text("E-STOP")
                await expect(tid("events")).to_contain_text("E-STOP pressed")
                await expect(tid("events")).to_contain_text(
                    "alarm 116: emergency stop button pressed", timeout=10_000
                )
                await page.screenshot(path=str(ARTIFACTS / "panel-estop.png"))

                # every Grafana query finds its series in the running cell's exporter
                text = (await api.get("/metrics")).text
                gaps = empty_selectors(text, {"cell": s.cell_id, "robot": s.gateway.robot_id})
                # pick_failure_total has a series only once a pick failed (none has, in this run)
                assert [g for g in gaps if not g.startswith("pick_failure_total")] == [], gaps

                # Reset (release + clear + enable), then Start: picking resumes in the same process
                await page.get_by_role("button", name="release e-stop and re-enable the arm").click()
                await expect(tid("robot-mode")).to_have_class(re.compile(r"\bok\b"), timeout=20_000)
                await expect(tid("robot-mode")).not_to_have_text("E-STOP")
                # (the task still reports ESTOP until it is started again: the header says so too)
                picks = tid("history").locator("tr.ok, tr.fail")
                before = await picks.count()
                await page.get_by_role("button", name="start the task").click()
                await expect(tid("state")).to_have_text(RUNNING_STATE, timeout=30_000)
                await expect(tid("events")).to_contain_text("e-stop released")
                # picking resumed: the next cycle runs to an outcome (the rod stands now, so vision
                # may find none: a failed pick is an outcome too) and it reaches the history
                await expect(picks).to_have_count(before + 1, timeout=240_000)
                assert not run.done()

                # the live link drops: everything greys out with "stale since", and recovers by itself
                await context.set_offline(True)
                await expect(page.locator("body")).to_have_attribute("data-stale", "true", timeout=15_000)
                await expect(tid("stale")).to_contain_text("stale since")
                await page.screenshot(path=str(ARTIFACTS / "panel-stale.png"))
                await context.set_offline(False)
                await expect(page.locator("body")).to_have_attribute("data-stale", "false", timeout=20_000)
                await expect(tid("stale")).to_be_hidden()
                await page.screenshot(path=str(ARTIFACTS / "panel-recovered.png"))
                assert not errors, f"JavaScript errors on the page: {errors}"
            finally:
                await browser.close()
    finally:
        run.cancel()  # Ctrl-C
        with pytest.raises(asyncio.CancelledError):
            await run
