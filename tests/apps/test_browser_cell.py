"""The dashboard on the real cell: every service, the twin and the embedded gateway, as
`pickplace up` runs them. Press Start in headless Chromium, see a real pick appear in the
history (its success judged by the task), and save a screenshot to ``artifacts/``."""

from __future__ import annotations

import pytest

from gateway.server import embedded_gateway
from services.apps.cell import Cell
from tests.apps.conftest import cell_settings
from tests.gateway.test_browser import ARTIFACTS, CHROMIUM, CHROMIUM_ARGS, CHROMIUM_INSTALLED

pytestmark = [pytest.mark.integration, pytest.mark.slow]


async def test_dashboard_start_runs_a_real_pick(tmp_path):
    from playwright.async_api import async_playwright, expect

    assert CHROMIUM_INSTALLED, (
        "Debian's chromium is missing: `make install` installs it (apt-get install chromium)"
    )
    s = cell_settings(
        tmp_path, gateway={"port": 0}, database={"url": f"sqlite+aiosqlite:///{tmp_path / 'cell.db'}"}
    )
    async with Cell(s, seed=3) as cell, embedded_gateway(cell.settings, cell.bus) as (_server, url):
        async with async_playwright() as pw:
            browser = await pw.chromium.launch(
                executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
            )
            try:
                page = await browser.new_page(viewport={"width": 1280, "height": 800})
                errors: list[str] = []
                page.on("pageerror", lambda exc: errors.append(str(exc)))
                await page.goto(url)
                await expect(page.get_by_test_id("robot-mode")).to_have_text("ENABLE", timeout=20_000)
                await expect(page.locator("#camera-img")).to_be_visible(timeout=20_000)  # the vision overlay
                await page.get_by_role("button", name="start the task").click()
                # one real pick-and-stand in the twin: detect, plan, move, place
                await expect(page.get_by_test_id("history").locator("tr.ok")).to_have_count(
                    1, timeout=120_000
                )
                await expect(page.get_by_test_id("success-rate")).to_have_text("100.0 %", timeout=10_000)
                ARTIFACTS.mkdir(exist_ok=True)
                await page.screenshot(path=str(ARTIFACTS / "dashboard-cell.png"))
                assert not errors, f"JavaScript errors on the page: {errors}"
            finally:
                await browser.close()
        await cell.task.runner.stop()
