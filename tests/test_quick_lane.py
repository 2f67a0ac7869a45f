"""The quick lane for development, ``pytest -m "not slow"``: the tests marked slow (the
marker of pyproject.toml) are left out, among them every test that drives Debian's chromium
or runs the line live over TCP; ``make test`` and CI select no marker and run them all."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: the tests that drive a browser or run the line live: slow by nature, whatever the machine
BROWSER_AND_LIVE = [
    "tests/web/test_dashboard_browser.py",
    "tests/web/test_live_dashboard.py",
    "tests/web/test_demo_screenshot.py::test_the_demo_writes_a_screenshot_with_every_train",
    "tests/net/test_loadtest.py::test_dashboard_loadtest_reports_what_the_page_drew",
    "tests/cosim/test_live.py::test_live_run_gives_the_co_simulations_kpis_within_the_stated_tolerance",
    "tests/cosim/test_live.py::test_live_run_went_over_the_real_link_on_the_run_s_clock",
    "tests/cosim/test_live.py::test_the_scenario_s_radio_stood_between_the_trains_and_the_ground_live",
    "tests/cosim/test_live.py::test_the_dashboard_was_photographed_during_the_live_run",
]


#: Run in a process of its own: collect with the given arguments and print, for each test
#: selected, its id and whether it is marked slow.
COLLECTOR = """
import json, sys
import pytest

class Marks:
    found = {}

    def pytest_collection_finish(self, session):
        for item in session.items:
            self.found[item.nodeid] = item.get_closest_marker("slow") is not None

marks = Marks()
code = pytest.main(["--collect-only", "-q", "-p", "no:cacheprovider", *sys.argv[1:]], [marks])
print("MARKS" + json.dumps(marks.found))
sys.exit(int(code))
"""


def _collected(*args: str) -> dict[str, bool]:
    """The test ids ``pytest --collect-only`` selects with ``args``, each with whether it is
    marked slow; one collection, in a process of its own."""
    done = subprocess.run(
        [sys.executable, "-c", COLLECTOR, *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    # 5: no test selected
    assert done.returncode in (0, 5), done.stdout[-3000:] + done.stderr[-3000:]
    line = next(line for line in done.stdout.splitlines() if line.startswith("MARKS"))
    found: dict[str, bool] = json.loads(line.removeprefix("MARKS"))
    return found


def _is_under(nodeid: str, target: str) -> bool:
    """Is the test ``nodeid`` the ``target`` (a file, a test) or one of its cases?"""
    return nodeid == target or nodeid.startswith((f"{target}::", f"{target}["))


def _marked(session: pytest.Session, *targets: str) -> dict[str, bool]:
    """The tests under ``targets`` with whether each is marked slow: read from this
    session's own collection when it holds every target (``make test`` collects the
    whole suite on every worker), else collected afresh (:func:`_collected`)."""
    mine = {
        item.nodeid: item.get_closest_marker("slow") is not None
        for item in session.items
        if any(_is_under(item.nodeid, t) for t in targets)
    }
    if all(any(_is_under(test, t) for test in mine) for t in targets):
        return mine
    return _collected(*targets)


# a collection of the whole web package and more, when this session has not collected them
@pytest.mark.slow
def test_every_browser_and_live_test_is_slow_and_the_quick_lane_keeps_the_rest(
    request: pytest.FixtureRequest,
) -> None:
    marked = _marked(request.session, *BROWSER_AND_LIVE, "tests/cosim/test_live.py")
    slow = {test for test, is_slow in marked.items() if is_slow}
    assert slow, "the slow set is empty"
    for target in BROWSER_AND_LIVE:
        assert any(test == target or test.startswith(f"{target}::") for test in slow), target
    # tests/cosim/test_live.py's signal cases run no live line: the quick lane keeps them
    quick = set(marked) - slow
    assert quick, "the quick lane is empty"
    assert all(test.startswith("tests/cosim/test_live.py::") for test in quick), sorted(quick)
