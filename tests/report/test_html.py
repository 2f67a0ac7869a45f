"""The HTML report: one page with every section's findings, tables and figures."""

from __future__ import annotations

from pathlib import Path

from railpilot.report.html import write_report
from railpilot.reproduce.base import Reproduction, Table


def _section(out: Path) -> Reproduction:
    figure = out / "figs" / "speed.png"
    figure.parent.mkdir(parents=True)
    figure.write_bytes(b"\x89PNG\r\n\x1a\n")
    table = Table(
        "Stop errors", ["controller", "stop error [m]"], [["PID", -0.0402], ["<b>", None]]
    )
    return Reproduction(
        "smarc-ep", "Paper 000 & friends", {}, [table], [figure], ["SMARC tracks <better>"]
    )


def test_report_links_figures_relative_to_the_page(tmp_path: Path) -> None:
    index = write_report([_section(tmp_path)], tmp_path)
    page = index.read_text()
    assert index == tmp_path / "index.html"
    assert "src='figs/speed.png'" in page


def test_report_shows_tables_findings_and_how_to_rerun(tmp_path: Path) -> None:
    page = write_report([_section(tmp_path)], tmp_path).read_text()
    assert "<td>-0.0402</td>" in page
    assert "<td>—</td>" in page  # a missing value is a dash, not 'None'
    assert "railpilot reproduce smarc-ep --json" in page
    assert "href='#smarc-ep'" in page


def test_report_escapes_text(tmp_path: Path) -> None:
    page = write_report([_section(tmp_path)], tmp_path).read_text()
    assert "&lt;better&gt;" in page and "<better>" not in page
    assert "&lt;b&gt;" in page
    assert "Paper 000 &amp; friends" in page


def test_a_section_with_its_own_commands_names_them_to_rerun(tmp_path: Path) -> None:
    section = _section(tmp_path)
    section.rerun = ("railpilot drive heavy-haul --from 1 --to 2", "railpilot drive a<b")
    page = write_report([section], tmp_path).read_text()
    assert "<code>railpilot drive heavy-haul --from 1 --to 2</code>" in page
    assert "<code>railpilot drive a&lt;b</code>" in page
    assert "railpilot reproduce smarc-ep" not in page
