"""Debian's chromium for Playwright: where it is and how it is started (no browser download).

One place for the tests (tests/web/conftest.py) and the report's screenshot
(reproduce/dashboard.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: Debian's chromium (``apt-get install chromium``; .ci/run installs it).
CHROMIUM = Path("/usr/bin/chromium")
#: Headless, no sandbox (containers), nothing fetched from the network.
CHROMIUM_FLAGS: tuple[str, ...] = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)


def missing_browser() -> str | None:
    """Why no screenshot can be taken here (None: chromium and Playwright are there)."""
    if not CHROMIUM.exists():
        return f"Debian's chromium is not installed at {CHROMIUM} (apt-get install chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ModuleNotFoundError:
        return "Playwright for Python is not installed (pip install pytest-playwright)"
    return None


def dashboard_screenshot(url: str, path: Path, trains: int, wait_s: float = 30.0) -> dict[str, Any]:
    """A full-page screenshot of the dashboard at ``url`` into ``path`` once it shows at
    least ``trains`` trains (a live line run's, cosim/live.py); what it showed, or why
    none was taken (``skipped``)."""
    missing = missing_browser()
    if missing is not None:
        return {"screenshot": None, "skipped": missing}
    from playwright.sync_api import expect, sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=str(CHROMIUM), args=list(CHROMIUM_FLAGS)
        )
        try:
            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            page.goto(url)
            rows = page.locator("#trains tbody tr[data-train]")
            # at least the trains the run knows on the line: the page also lists, greyed,
            # a train that has left it, and an exact count failed on a busy machine (3
            # rows for 2 on the line)
            if trains > 0:
                expect(rows.nth(trains - 1)).to_be_attached(timeout=wait_s * 1000)
            page.screenshot(path=str(path), full_page=True)
            shown = rows.count()
            # each train's category as the page wrote it (" · freight_loaded"), by train id
            categories = {
                str(row.get_attribute("data-train")): text.lstrip(" ·")
                for row in rows.all()
                for text in row.locator(".category").all_inner_texts()
            }
        finally:
            browser.close()
    return {"screenshot": str(path), "trains_shown": shown, "categories_shown": categories}
