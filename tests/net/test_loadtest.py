"""A small load test: the report has the documented keys and nothing is lost (not timed)."""

from __future__ import annotations

from railpilot.net.loadtest import LoadtestOptions, run_loadtest

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
