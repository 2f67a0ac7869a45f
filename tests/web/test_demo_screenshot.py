"""The report's dashboard screenshot (`railpilot reproduce dashboard`, part of make demo)."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest

from railpilot.reproduce import dashboard

from .conftest import needs_chromium


@pytest.mark.slow
@pytest.mark.browser
@needs_chromium
def test_the_demo_writes_a_screenshot_with_every_train(tmp_path: Path) -> None:
    # in a thread of its own, as in `make demo`: pytest-playwright's browser tests leave an
    # event loop running in this thread, and Playwright's sync API refuses to start there
    results: list[Any] = []
    worker = threading.Thread(target=lambda: results.append(dashboard.run(tmp_path)))
    worker.start()
    worker.join(120.0)
    assert not worker.is_alive(), "the screenshot did not finish"
    (reproduction,) = results
    (figure,) = reproduction.figures
    assert figure == tmp_path / "dashboard.png"
    # a full page of a 1600 px wide dashboard, not an empty or error page
    assert figure.stat().st_size > 100_000
    # read from the live ground at the screenshot: at least 20 trains over TCP, and the
    # form's TSR acknowledged by every train it went to
    seen = reproduction.payload
    assert seen["trains_registered"] >= 20
    assert seen["tsr_concerned"] and seen["tsr_acknowledged"] == seen["tsr_concerned"]
    # the two trains standing one behind the other: the follower is held behind the first
    assert seen["targets"]["8002"]["reason"] == "TRAIN_AHEAD"
    assert 141.0 < seen["targets"]["8002"]["km"] < 150.0 - dashboard.LENGTH_M / 1000.0


def test_without_chromium_the_report_says_so_and_shows_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import railpilot.web.browser as browser

    monkeypatch.setattr(browser, "CHROMIUM", tmp_path / "no-chromium")
    reproduction = dashboard.run(tmp_path)
    assert reproduction.figures == []
    assert reproduction.payload["screenshot"] is None
    assert "chromium is not installed" in reproduction.findings[0]
    assert not (tmp_path / "dashboard.png").exists()
