"""``--out``: a folder that cannot be written is refused when the command line is read,
before anything runs (it failed only when the results were written: after a whole run
or sweep, with some files already written)."""

from __future__ import annotations

from pathlib import Path

import pytest

from railpilot.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
COMMANDS = {
    "simulate": ["simulate", str(EXAMPLES / "eddy_case2.toml")],
    "montecarlo": ["montecarlo", str(EXAMPLES / "paper000_montecarlo.toml"), "--runs", "2"],
    "line simulate": ["line", "simulate", str(EXAMPLES / "line_live_short.toml")],
    "drive": ["drive", "heavy-haul", "--from", "1", "--to", "2"],
    "reproduce": ["reproduce", "eddy-torque"],
    "demo": ["demo"],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("where", ["a file", "under a file", "deeper under a file"])
def test_an_out_folder_that_cannot_be_made_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, where: str
) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    out = {"a file": a_file, "under a file": a_file / "out", "deeper under a file": a_file / "a/b"}
    with pytest.raises(SystemExit) as exit_:
        main([*COMMANDS[command], "--out", str(out[where])])
    assert exit_.value.code == 2
    captured = capsys.readouterr()
    assert f"--out = '{out[where]}' is not allowed: expected a folder" in captured.err
    assert captured.out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]


def test_the_default_out_folder_is_checked_too(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").write_text("not a folder")
    with pytest.raises(SystemExit) as exit_:
        main(["reproduce", "eddy-torque"])
    assert exit_.value.code == 2
    assert (
        "--out = 'out' is not allowed: expected a folder (it is a file)" in capsys.readouterr().err
    )
