"""railpilot.textfile: a file the user named is read, or refused naming the option."""

from __future__ import annotations

from pathlib import Path

import pytest

from railpilot.errors import ConfigError, ScenarioError
from railpilot.textfile import read_text, read_toml


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    (tmp_path / "a_dir").mkdir()
    (tmp_path / "a_file").write_text("x = 1\n")
    (tmp_path / "latin1.toml").write_bytes("name = 'Kl\xf6ster'\n".encode("latin-1"))
    (tmp_path / "bad.toml").write_text("x = \n")
    return {
        "missing": tmp_path / "missing.toml",
        "a directory": tmp_path / "a_dir",
        "under a file": tmp_path / "a_file" / "x.toml",
        "not UTF-8": tmp_path / "latin1.toml",
        "bad TOML": tmp_path / "bad.toml",
        "good": tmp_path / "a_file",
    }


@pytest.mark.parametrize(
    ("case", "allowed"),
    [
        ("missing", "an existing timetable file"),
        ("a directory", "a readable timetable file (Is a directory)"),
        ("under a file", "a readable timetable file (Not a directory)"),
        ("not UTF-8", "a UTF-8 text timetable file"),
        ("bad TOML", "valid TOML (Invalid value (at line 1, column 5))"),
    ],
)
def test_a_path_that_is_no_readable_file_is_refused_naming_the_option(
    files: dict[str, Path], case: str, allowed: str
) -> None:
    with pytest.raises(ConfigError) as info:
        read_toml(files[case], "--timetable", "timetable file")
    assert (info.value.field, info.value.value) == ("--timetable", str(files[case]))
    assert info.value.allowed.startswith(allowed)


def test_the_caller_s_error_class_and_a_good_file(files: dict[str, Path]) -> None:
    with pytest.raises(ScenarioError):
        read_text(files["a directory"], "SCENARIO", "line-run file", ScenarioError)
    assert read_toml(files["good"], "SCENARIO", "TOML file") == {"x": 1}
    assert read_text(files["good"], "SCENARIO", "TOML file") == "x = 1\n"
