"""``railpilot demo``'s section of heavy-haul drives on the consist model: each drive's
figure written under the report and shown on its page, with the command that gives it."""

from __future__ import annotations

from pathlib import Path

import pytest

from railpilot.cli import main
from railpilot.commands import demo


def test_the_demo_report_shows_a_figure_per_driven_section(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # the reproductions left out, and one short section: the report's drive section alone
    one = (demo.DemoDrive("heavy-haul-loaded", 1, 2, timetabled=True),)
    monkeypatch.setattr(demo, "REPRODUCTIONS", {})
    monkeypatch.setattr(demo, "DEMO_DRIVES", one)
    assert main(["demo", "--out", str(tmp_path)]) == 0
    page = (tmp_path / "index.html").read_text()
    figure = "drive-cycles/heavy-haul-loaded_1-2_cycles.png"
    assert (tmp_path / figure).stat().st_size > 0
    assert f"src='{figure}'" in page
    assert "href='#drive-cycles'" in page
    rerun = "railpilot drive heavy-haul --train heavy-haul-loaded --from 1 --to 2 --timetable"
    assert rerun in page
    assert "railpilot reproduce drive-cycles" not in page  # no such reproduction
    assert "<td>1 -&gt; 2</td>" in page  # its row in the table
    assert "1 -> 2" in capsys.readouterr().out  # its table printed, as every section's


def test_the_drive_section_follows_the_heavy_haul_train_s_published_figures() -> None:
    names = [name for name, _ in demo._sections()]
    assert names.count("drive-cycles") == 1
    assert names.index("drive-cycles") == names.index("heavy-haul-ltd") + 1
    assert names[-1] == "dashboard"  # still last (module railpilot.reproduce)
