"""Load tests: the report has the documented keys and nothing is lost (nothing here is timed:
benchmarks/front_server_capacity.py measures), the trains run on the line, and the
dashboard run (Debian's chromium) reports what the page drew."""

from __future__ import annotations

import struct
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from railpilot import cli
from railpilot.line.loader import load_line
from railpilot.line.model import DOWN, UP
from railpilot.rigs.loadtest import (
    SPEED_SHARE,
    LoadtestOptions,
    dashboard_report,
    layout,
    run_loadtest,
)
from railpilot.web import browser
from railpilot.web.app import Push

KEYS = (
    "trains",
    "seconds",
    "messages_sent",
    "messages_received",
    "lost",
    "p50_latency_ms",
    "p99_latency_ms",
    "tsr_sent",
    "tsr_acknowledged",
)
DASHBOARD_KEYS = (
    "renders",
    "updates_per_s",
    "max_gap_s",
    "render_ms_p50",
    "pushes_in_window",
    "snapshot_ms_p50",
    "snapshot_ms_p99",
    "snapshot_build_ms_p50",
    "snapshot_encode_ms_p50",
    "snapshot_bytes",
    "trains_drawn",
    "train_rows",
    "errors",
)


@pytest.mark.slow
def test_small_loadtest_reports_every_key_and_loses_nothing() -> None:
    report = run_loadtest(LoadtestOptions(trains=20, seconds=3.0, drain_s=3.0))
    assert set(KEYS) <= set(report)
    assert report["trains"] == 20
    assert report["messages_sent"] > 0
    assert report["lost"] == 0
    assert report["messages_received"] == report["messages_sent"]
    assert report["tsr_sent"] == report["tsr_acknowledged"] == 20
    assert report["tsr_applied_more_than_once"] == 0
    assert report["p50_latency_ms"] is not None and report["p99_latency_ms"] is not None
    assert "dashboard" not in report and report["dispatch"] is False


# --- where the trains run


def test_trains_are_spread_over_the_line_both_ways_below_its_limits() -> None:
    line = load_line("heavy-haul")
    options = LoadtestOptions(trains=200, seconds=30.0)
    trajectories = layout(options, line)
    assert sorted(trajectories) == list(options.train_ids())
    ups = [t for t in trajectories.values() if t.direction is UP]
    downs = [t for t in trajectories.values() if t.direction is DOWN]
    assert len(ups) == len(downs) == 100
    run_s = options.ramp + options.seconds + options.drain_s + 10.0
    for travel, trains in ((UP, ups), (DOWN, downs)):
        starts = sorted(t.start_m for t in trains)
        # spread along the line (both halves), not bunched at one end
        tenth = 0.1 * (line.end_m - line.start_m)
        assert starts[0] < line.start_m + tenth
        assert starts[-1] > line.end_m - tenth
        category = line.categories[0] if travel is UP else line.categories[-1]
        for train in trains:
            end_m, _ = train.state(run_s)
            assert line.start_m < min(train.start_m, end_m)
            assert max(train.start_m, end_m) < line.end_m
            low, high = sorted((train.start_m, end_m))
            limits = [float(line.limit_at(category, travel, x)) for x in (low, high)]
            assert 0 < train.speed_mps <= SPEED_SHARE[1] * min(limits)
    # the same seed, the same trains
    assert layout(options, line) == trajectories


# --- the dashboard's numbers, from what the page and the server recorded


def test_dashboard_report_counts_renders_and_gaps_in_the_steady_window() -> None:
    w0, w1 = 100.0, 110.0
    at_s = [99.5, 100.4, 101.4, 102.4, 104.9, 105.9, 106.9, 107.9, 108.9, 109.6]
    page = {
        "renders": len(at_s),
        "render_at_ms": [t * 1000.0 for t in at_s],
        "render_ms": [5.0] * len(at_s),
        "paint_ms": [20.0] * (len(at_s) - 1) + [None],  # the last frame not painted yet
        "versions": list(range(len(at_s))),
        "trains_shown": 3,
        "rows": 3,
        "status": "live",
        "errors": [],
        "screenshot": None,
    }
    pushes = [Push(0.0, 0.010, 0.002, 1000), Push(1.0, 0.030, 0.004, 3000)]
    report = dashboard_report(page, pushes, (w0, w1))
    assert report["renders_in_window"] == 9  # 99.5 is before the window
    assert report["updates_per_s"] == pytest.approx(0.9)
    assert report["max_gap_s"] == pytest.approx(2.5)  # 102.4 -> 104.9
    assert report["pushes_in_window"] == 2
    assert report["snapshot_ms_p50"] == pytest.approx(12.0)
    assert report["snapshot_ms_max"] == pytest.approx(34.0)
    assert report["snapshot_bytes"] == 3000
    assert report["paint_ms_p50"] == pytest.approx(20.0)


def test_dashboard_report_counts_a_page_that_stopped_drawing() -> None:
    page = {
        "renders": 1,
        "render_at_ms": [99_000.0],
        "render_ms": [5.0],
        "paint_ms": [20.0],
        "versions": [1],
        "trains_shown": 0,
        "rows": 0,
        "status": "live",
        "errors": [],
        "screenshot": None,
    }
    report = dashboard_report(page, [], (100.0, 110.0))
    assert report["renders_in_window"] == 0
    assert report["updates_per_s"] == 0.0
    assert report["max_gap_s"] == pytest.approx(11.0)  # from the last render to the end
    assert report["snapshot_ms_p50"] is None


# --- the command line


def test_dashboard_without_chromium_exits_2_naming_the_option(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = tmp_path / "no-chromium"
    monkeypatch.setattr(browser, "CHROMIUM", missing)
    code = cli.main(["link", "loadtest", "--trains", "2", "--seconds", "1", "--dashboard"])
    assert code == 2
    err = capsys.readouterr().err
    assert "--dashboard" in err and str(missing) in err
    assert "Traceback" not in err


def test_screenshot_without_dashboard_exits_2_naming_the_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    shot = tmp_path / "page.png"
    code = cli.main(["link", "loadtest", "--trains", "2", "--screenshot", str(shot)])
    assert code == 2
    assert "--screenshot" in capsys.readouterr().err
    assert not shot.exists()


# --- with the page open in chromium


@pytest.mark.slow
@pytest.mark.browser
@pytest.mark.skipif(
    not browser.CHROMIUM.exists(),
    reason=f"Debian's chromium is not installed at {browser.CHROMIUM} (apt-get install "
    "chromium; .ci/run does it): the --dashboard load test opens the page in it",
)
def test_dashboard_loadtest_reports_what_the_page_drew(tmp_path: Path) -> None:
    shot = tmp_path / "page.png"
    options = LoadtestOptions(trains=20, seconds=4.0, dashboard=True, screenshot=str(shot))
    # in a thread of its own: after pytest-playwright's browser tests the main thread
    # keeps an event loop marked running, and run_loadtest starts one (asyncio.run)
    with ThreadPoolExecutor(1) as pool:
        report = pool.submit(run_loadtest, options).result(timeout=120.0)
    assert report["lost"] == 0
    assert report["dispatch"] is True
    page = report["dashboard"]
    assert "error" not in page, page
    assert set(DASHBOARD_KEYS) <= set(page)
    assert page["errors"] == []
    assert page["status"] == "live"
    assert page["renders"] > 0
    assert page["pushes_in_window"] > 0
    assert page["snapshot_ms_p50"] is not None and page["snapshot_ms_p50"] >= 0
    assert page["snapshot_bytes"] > 0
    assert page["train_rows"] == 20  # a row per train in the trains table
    assert page["trains_drawn"] >= 20  # a train may be drawn on two rows of the diagram
    header = shot.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    assert struct.unpack(">II", header[16:24]) == (1600, 1000)
