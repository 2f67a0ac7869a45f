"""The dashboard end to end in headless chromium (Playwright, Debian's chromium).

The server runs in a thread (conftest.served); the page gets its snapshots over the
WebSocket. Time on the made-up line moves only when the test advances it, and every wait
is Playwright's ``expect`` polling up to a deadline: no sleeps, no timed assertions.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import pytest
from playwright.sync_api import Locator, Page, expect

from railpilot.cosim.demo_ground import DemoGround
from railpilot.link.ground import TsrState

from .conftest import STARTING, TOKEN, Served, StartingGround, needs_chromium, serve

pytestmark = [needs_chromium, pytest.mark.slow]

#: Longest wait for the page to show what the ground holds [ms].
SHOWN_MS = 10_000
#: The train whose link failed on the demo line (conftest.ground): nothing reaches it.
NO_LINK = 1016


def _open(page: Page, served: Served) -> None:
    page.goto(served.url)
    expect(page.locator("#status")).to_have_text("live", timeout=SHOWN_MS)
    expect(page.locator("#trains tbody tr[data-train]")).to_have_count(24, timeout=SHOWN_MS)


def _enter_token(page: Page) -> None:
    page.fill("#token", TOKEN)
    page.click("#token-save")
    expect(page.locator("#token-state")).to_contain_text("token in use")


def _fill_tsr(page: Page, **fields: str) -> None:
    for name, value in fields.items():
        page.fill(f"#f-{name}", value)
    page.click("#tsr-submit")


def _delivery(page: Page, session: int, train: int) -> Locator:
    return page.locator(f'#tsrs [data-session="{session}"][data-train="{train}"] .state')


def test_dispatcher_sets_a_tsr_and_watches_each_acknowledgement(
    served: Served, page: Page, tmp_path: Path
) -> None:
    ground = served.ground
    _open(page, served)
    _enter_token(page)
    _fill_tsr(
        page,
        start_km="300",
        end_km="330",
        limit_kmh="40",
        valid_from_min="0",
        valid_until_min="90",
        reason="sun kink check",
    )
    # a demo train runs at 75 km/h inside km 300-330: the ground sends nothing and asks
    expect(page.locator("#tsr-warning li[data-train]")).not_to_have_count(0, timeout=SHOWN_MS)
    expect(page.locator("#tsr-result")).to_have_text("")
    assert [t["session"] for t in ground.snapshot(ground.now_s())["tsrs"]] == [1]
    page.click("#tsr-confirm")
    expect(page.locator("#tsr-result")).to_contain_text("TSR 2 set", timeout=SHOWN_MS)
    expect(page.locator("#tsr-warning")).to_be_hidden()
    concerned = [t for t in ground.train_ids() if ground.delivery_state(2, t) is not None]
    assert len(concerned) >= 4 and NO_LINK in concerned
    for train in concerned:  # sent, not yet acknowledged: time has not moved
        expect(_delivery(page, 2, train)).to_have_text("PENDING_SET", timeout=SHOWN_MS)

    waiting = set(concerned) - {NO_LINK}
    for _ in range(10):  # the acknowledgements come back 1 to 5 s after the delivery
        if not waiting:
            break
        ground.advance(1.0)
        acknowledged = {t for t in waiting if ground.delivery_state(2, t) is TsrState.ACTIVE}
        for train in sorted(acknowledged):
            expect(_delivery(page, 2, train)).to_have_text("ACTIVE", timeout=SHOWN_MS)
        waiting -= acknowledged
    assert not waiting, f"trains that never acknowledged: {sorted(waiting)}"
    expect(_delivery(page, 2, NO_LINK)).to_have_text("PENDING_SET")
    expect(page.locator("#line .tsr text", has_text="TSR 2 · 40")).not_to_have_count(0)
    page.screenshot(path=tmp_path / "acknowledged.png", full_page=True)


def test_a_bad_value_is_shown_next_to_its_field(served: Served, page: Page) -> None:
    _open(page, served)
    _fill_tsr(page, start_km="300", end_km="330", limit_kmh="40", reason="x")
    expect(page.locator("#err-token")).to_contain_text("token first")  # nothing sent yet

    _enter_token(page)
    _fill_tsr(page, start_km="300", end_km="290", limit_kmh="fast", reason="check")
    expect(page.locator("#err-limit_kmh")).to_contain_text("'fast' is not allowed")
    expect(page.locator("#f-limit_kmh")).to_have_attribute("aria-invalid", "true")
    expect(page.locator("#err-start_km")).to_have_text("")

    _fill_tsr(page, limit_kmh="40")  # now the km range is what is wrong
    expect(page.locator("#err-end_km")).to_contain_text("above start_km = 300")
    expect(page.locator("#err-limit_kmh")).to_have_text("")
    assert [t["session"] for t in served.ground.snapshot(served.ground.now_s())["tsrs"]] == [1]


def test_a_dispatcher_cancels_a_tsr_after_confirming(served: Served, page: Page) -> None:
    _open(page, served)
    _enter_token(page)
    cancel = page.locator('#tsrs button[data-cancel="1"]')
    cancel.click()
    expect(cancel).to_have_text("Confirm cancel")
    cancel.click()
    expect(page.locator("#tsr-result")).to_contain_text("TSR 1 cancelled", timeout=SHOWN_MS)
    served.ground.advance(6.0)
    expect(page.locator('#tsrs tr[data-session="1"] td').nth(5)).to_contain_text(
        "CANCELLED", timeout=SHOWN_MS
    )
    expect(_delivery(page, 1, 1001)).to_have_text("CANCELLED", timeout=SHOWN_MS)


def _png_size(path: Path) -> tuple[int, int]:
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", header[16:24])
    return width, height


def test_screenshot_of_the_line_with_at_least_20_trains(
    served: Served, page: Page, tmp_path: Path
) -> None:
    _open(page, served)
    served.ground.advance(1.0)
    expect(page.locator("#line .train text")).to_have_count(24, timeout=SHOWN_MS)
    expect(page.locator("#alarms li[data-alarm]")).to_have_count(2)
    expect(page.locator("#line circle.signal.red")).not_to_have_count(0)
    path = tmp_path / "dashboard.png"
    page.screenshot(path=path, full_page=True)
    width, height = _png_size(path)
    assert width >= 1600 and height >= 1500
    assert path.stat().st_size > 100_000  # a drawn page, not a blank one


def test_the_page_says_the_ground_is_starting_then_goes_live_by_itself(
    ground: DemoGround, page: Page
) -> None:
    source = StartingGround(ground)
    with serve(source) as url:
        page.goto(url)
        status = page.locator("#status")
        expect(status).to_have_text(re.compile(f"^{STARTING}"), timeout=SHOWN_MS)
        expect(status).to_have_class(re.compile("down"))
        expect(page.locator("#trains tbody tr[data-train]")).to_have_count(0)
        source.ready = True  # the page retries every second: no reload
        expect(status).to_have_text("live", timeout=SHOWN_MS)
        expect(page.locator("#trains tbody tr[data-train]")).to_have_count(24, timeout=SHOWN_MS)


def test_the_graph_fits_its_distance_axis_to_the_trains_until_asked_for_the_whole_line(
    page: Page, tmp_path: Path
) -> None:
    ground = DemoGround(2, seed=0, warmup_s=1800.0)  # one train each way, both mid-line
    stations = [st.name for st in ground.line.stations]
    with serve(ground) as url:
        page.goto(url)
        expect(page.locator("#status")).to_have_text("live", timeout=SHOWN_MS)
        expect(page.locator("#graph .train-label")).to_have_count(2, timeout=SHOWN_MS)
        labels = page.locator("#graph .station-label")
        shown = labels.all_text_contents()
        # the stretch the two trains cover, from a station to a station: not the line's ends
        assert 2 <= len(shown) < len(stations)
        assert stations[0] not in shown and stations[-1] not in shown
        assert shown == [name for name in stations if name in shown]  # in the line's order
        span = page.locator("#graph-span")
        expect(span).to_have_text(re.compile(r"^km \d+–\d+$"))
        km_from, km_to = (float(v) for v in span.inner_text()[3:].split("–"))
        # every point of every plan and run inside the plot (TD's top 20, bottom 600 - 26)
        ys = page.eval_on_selector_all(
            "#graph polyline",
            "lines => lines.flatMap(l => [...l.points].map(p => p.y))",
        )
        assert ys and min(ys) >= 20.0 - 1e-6 and max(ys) <= 574.0 + 1e-6
        assert max(ys) - min(ys) > 200.0  # the runs fill the axis, not a strip of it
        page.screenshot(path=tmp_path / "fitted.png", full_page=True)

        # the demo's TSR 1 (km 120-126.5, in force) lies outside the trains' stretch
        snap = ground.snapshot(ground.now_s())
        tsr = next(t for t in snap["tsrs"] if t["session"] == 1)
        assert tsr["state"] == "ACTIVE" and not km_from < tsr["end_km"] <= km_to
        band = page.locator('#graph .tsr[data-session="1"]')
        expect(band).to_have_count(0)

        page.click("#graph-whole")
        expect(labels).to_have_count(len(stations))
        expect(span).to_have_text("whole line")
        expect(page.locator("#graph-whole")).to_have_attribute("aria-pressed", "true")
        expect(band.locator("text")).to_have_text("TSR 1 · 45")
        # its height on the axis is its 6.5 km of the line's length (the plot 554 px high)
        top, height = band.locator("rect").evaluate(
            "r => [r.y.baseVal.value, r.height.baseVal.value]"
        )
        line_km = snap["line"]["end_km"] - snap["line"]["start_km"]
        assert height == pytest.approx(6.5 / line_km * 554.0, rel=1e-6)
        assert top == pytest.approx(20.0 + (120.0 - snap["line"]["start_km"]) / line_km * 554.0)
        ground.advance(1.0)  # a new snapshot keeps the dispatcher's choice
        expect(labels).to_have_count(len(stations))

        page.click("#graph-whole")
        expect(labels).to_have_count(len(shown))
        expect(page.locator("#graph-whole")).to_have_attribute("aria-pressed", "false")


def test_dispatcher_sends_a_command_and_watches_each_train_acknowledge_it(
    served: Served, page: Page
) -> None:
    ground = served.ground
    _open(page, served)
    page.click("#dispatch-submit")  # no token yet: nothing sent
    expect(page.locator("#err-token")).to_contain_text("token first")

    _enter_token(page)
    page.fill("#fd-trains", "1001, K1002")
    page.fill("#fd-text", "Hold at the next station")
    page.click("#dispatch-submit")
    expect(page.locator("#errd-trains")).to_contain_text("'1001, K1002' is not allowed")
    expect(page.locator("#fd-trains")).to_have_attribute("aria-invalid", "true")
    expect(page.locator("#errd-text")).to_have_text("")

    page.fill("#fd-trains", "1001, 1002")
    page.click("#dispatch-submit")
    expect(page.locator("#dispatch-result")).to_contain_text("sent to 2 train(s)")
    expect(page.locator("#errd-trains")).to_have_text("")
    number = max(row["command"] for row in ground.snapshot(ground.now_s())["dispatch"])
    rows = [
        page.locator(f'#dispatch tr[data-command="{number}"][data-train="{train}"]')
        for train in (1001, 1002)
    ]
    for row in rows:
        expect(row).to_contain_text("Hold at the next station", timeout=SHOWN_MS)
        expect(row.locator(".chip")).to_have_text("PENDING")
    ground.advance(6.0)  # every acknowledgement is back 1 to 5 s after the delivery
    for row in rows:
        expect(row.locator(".chip")).to_have_text("ACKNOWLEDGED", timeout=SHOWN_MS)


def test_dispatcher_declares_a_section_fault_and_clears_it_after_confirming(
    served: Served, page: Page
) -> None:
    _open(page, served)
    _enter_token(page)
    rows = page.locator("#restrictions tbody tr[data-restriction]")
    expect(rows).to_have_count(1)  # the demo's own section fault
    page.select_option("#fr-reason", "switch_indication_lost")
    page.fill("#fr-start_km", "251")
    page.fill("#fr-end_km", "250")
    page.click("#restriction-submit")
    expect(page.locator("#errr-end_km")).to_contain_text("above start_km")
    expect(page.locator("#fr-end_km")).to_have_attribute("aria-invalid", "true")

    page.fill("#fr-end_km", "252")
    page.select_option("#fr-track", "up")
    page.click("#restriction-submit")
    expect(page.locator("#restriction-result")).to_contain_text("declared")
    expect(rows).to_have_count(2)
    row = rows.nth(1)
    expect(row).to_contain_text("switch indication lost")
    expect(row).to_contain_text("km 251.000–252.000")
    held = row.locator("td").nth(4).inner_text().split(", ")
    for block in held:  # its blocks drawn restricted on the line diagram
        expect(page.locator(f'#line [data-block="{block}"].restricted')).not_to_have_count(0)

    row.locator("button").click()
    expect(row.locator("button")).to_have_text("Confirm clear")
    expect(rows).to_have_count(2)  # one click asks again
    row.locator("button").click()
    expect(rows).to_have_count(1, timeout=SHOWN_MS)
    expect(page.locator("#restriction-result")).to_contain_text("cleared")
