"""``railpilot validate FILE`` (railpilot.commands.validate): the shipped files are valid
and their format is guessed right; a broken copy exits 2 naming the key, prints nothing
on stdout and writes nothing."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from railpilot.cli import main
from railpilot.commands.validate import guess_format
from railpilot.schema.formats import FORMATS

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
LINES = ROOT / "src" / "railpilot" / "line" / "data"
CONSISTS = ROOT / "src" / "railpilot" / "vehicle" / "data" / "consists"

KEY_HEX = "ab" * 16

#: a valid file of each format and the words the ok line says of it
VALID = {
    "scenario": (EXAMPLES / "paper000_smarc_ep.toml", "braking scenario"),
    "eddy-brake": (EXAMPLES / "eddy_case1.toml", "eddy-current brake scenario"),
    "consist": (CONSISTS / "heavy_haul_10kt.toml", "consist file"),
    "line-run": (EXAMPLES / "line_short_day.toml", "line run"),
    "keys": (None, "key file"),  # written by the test: keys are never shipped
    "line": (LINES / "metro.toml", "line file"),
    "timetable": (LINES / "heavy_haul_timetable.toml", "timetable"),
    "train-dynamics": (EXAMPLES / "heavy_haul_ltd.toml", "train-dynamics scenario"),
    "consist-library": (
        CONSISTS / "library.toml",
        "library of vehicle types and draft gears a consist file may name",
    ),
}

#: every shipped file a user may copy, and its format
SHIPPED = {
    **{p: "scenario" for p in EXAMPLES.glob("paper00*.toml")},
    EXAMPLES / "heavy_haul_run.toml": "scenario",
    EXAMPLES / "heavy_haul_stop.toml": "scenario",
    EXAMPLES / "eddy_case1.toml": "eddy-brake",
    EXAMPLES / "eddy_case2.toml": "eddy-brake",
    EXAMPLES / "heavy_haul_ltd.toml": "train-dynamics",
    EXAMPLES / "heavy_haul_20kt_dp.toml": "train-dynamics",
    EXAMPLES / "heavy_haul_day.toml": "line-run",
    EXAMPLES / "line_short_day.toml": "line-run",
    EXAMPLES / "line_live_short.toml": "line-run",
    LINES / "heavy_haul.toml": "line",
    LINES / "metro.toml": "line",
    LINES / "heavy_haul_timetable.toml": "timetable",
    CONSISTS / "heavy_haul_10kt.toml": "consist",
    CONSISTS / "heavy_haul_10kt_empty.toml": "consist",
    CONSISTS / "heavy_haul_20kt_dp.toml": "consist",
    CONSISTS / "library.toml": "consist-library",
}


def key_file(folder: Path, train_id: str = "7", mode: int = 0o600) -> Path:
    path = folder / "keys.toml"
    path.write_text(f'[[train]]\nid = {train_id}\n[train.keys]\n1 = "{KEY_HEX}"\n')
    path.chmod(mode)
    return path


def validate(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["validate", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_every_format_has_a_case():
    assert set(VALID) == set(FORMATS)


@pytest.mark.parametrize("name", list(VALID))
def test_a_valid_file_prints_one_line(name, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path, words = VALID[name]
    if path is None:
        path = key_file(tmp_path)
    before = sorted(tmp_path.iterdir())
    code, out, err = validate(capsys, str(path), "--as", name)
    assert (code, out, err) == (0, f"{path}: a valid {words} ({name})\n", "")
    assert sorted(tmp_path.iterdir()) == before  # nothing written


@pytest.mark.parametrize("path", sorted(SHIPPED), ids=lambda p: p.name)
def test_the_format_of_every_shipped_file_is_guessed(path, capsys):
    code, out, _ = validate(capsys, str(path))
    assert code == 0
    assert out.endswith(f"({SHIPPED[path]})\n")


def test_every_example_is_in_the_guess_test():
    assert set(EXAMPLES.glob("*.toml")) <= set(SHIPPED)


def test_the_key_file_is_guessed(capsys, tmp_path):
    path = key_file(tmp_path)
    assert validate(capsys, str(path))[:2] == (0, f"{path}: a valid key file (keys)\n")


@pytest.mark.parametrize(
    ("data", "name"),
    [
        ({"kind": "eddy-brake"}, "eddy-brake"),
        ({"kind": "train-dynamics", "line": {}}, "train-dynamics"),
        ({"kind": "some-other"}, "scenario"),  # simulate's reader names the kinds it knows
        ({"name": "x", "services": [], "line": "heavy-haul"}, "line-run"),
        ({"sections": []}, "timetable"),
        ({"name": "x", "categories": ["metro"]}, "line"),
        ({"train": [{"id": 1, "keys": {}}]}, "keys"),
        ({"name": "x", "train": [{"type": "C80", "count": 1}]}, "consist"),
        ({"draft_gears": {}}, "consist-library"),
        ({"name": "x", "train": {"mass_t": 1.0}}, "scenario"),
        ({"name": "x"}, None),
        ([1, 2], None),
    ],
)
def test_the_guess(data, name):
    assert guess_format(data) == name


# --- broken copies ----------------------------------------------------------------------

#: (format, file, a line of it (regex), what replaces it, the key the error must name)
BROKEN = [
    ("scenario", "paper000_smarc_ep.toml", r"^mass_t = .*$", "mass_t = -536.0", "train.mass_t"),
    ("scenario", "paper000_smarc_ep.toml", r'^name = ".*"$', "", "name"),
    (
        "eddy-brake",
        "eddy_case1.toml",
        r"^torque_demand_nm = .*$",
        "torque_demand_nm = -5",
        "torque_demand_nm",
    ),
    ("eddy-brake", "eddy_case1.toml", r"^initial_speed_kmh = .*$", "", "initial_speed_kmh"),
    ("eddy-brake", "eddy_case1.toml", r"^kind = .*$", "", "kind"),
    ("consist", "heavy_haul_10kt.toml", r"^count = 105$", "count = 0", "count"),
    ("consist", "heavy_haul_10kt.toml", r'^name = ".*"$', "", "name"),
    ("line-run", "line_short_day.toml", r"^loss = .*$", "loss = 7.0", "loss"),
    (
        "line-run",
        "line_short_day.toml",
        r"^dead_zones = .*$",
        "dead_zones = [{ start_km = 900.0, end_km = 901.0 }]",
        "dead_zones",
    ),
    ("line", "metro.toml", r"^end_km = .*$", "end_km = -3.0", "end_km"),
    ("line", "metro.toml", r"^categories = .*$", "", "categories"),
    (
        "timetable",
        "heavy_haul_timetable.toml",
        r"^running_time_s = 1470\.0.*$",
        "running_time_s = -1.0",
        "running_time_s",
    ),
    ("timetable", "heavy_haul_timetable.toml", r"^to = 2$", "", "to"),
    ("timetable", "heavy_haul_timetable.toml", r"^to = 2$", "to = 99", "to"),  # no such station
    ("train-dynamics", "heavy_haul_ltd.toml", r"^dt_s = .*$", "dt_s = -0.05", "dt_s"),
    ("train-dynamics", "heavy_haul_ltd.toml", r'^name = ".*"$', "", "name"),
    (
        "consist-library",
        "library.toml",
        r"^unloading_ratio = .*$",
        "unloading_ratio = 3.0",
        "unloading_ratio",
    ),
    ("consist-library", "library.toml", r"^travel_mm = .*$", "", "travel_mm"),
    ("keys", None, r"^id = 7$", "id = 0", "train[0].id"),
    ("keys", None, r"^\[train\.keys\]$", "", "keys"),
]

_FOLDERS = {"eddy-brake": EXAMPLES, "scenario": EXAMPLES, "line-run": EXAMPLES}
_FOLDERS |= {"train-dynamics": EXAMPLES, "line": LINES, "timetable": LINES}
_FOLDERS |= {"consist": CONSISTS, "consist-library": CONSISTS}


def broken_copy(folder: Path, name: str, file: str | None, line: str, new: str) -> Path:
    """The shipped file (or a key file) with its first line matching ``line`` replaced."""
    if file is None:
        (folder / "src").mkdir()
        source = key_file(folder / "src")
    else:
        source = _FOLDERS[name] / file
    text, count = re.subn(line, new, source.read_text(), count=1, flags=re.MULTILINE)
    assert count == 1, f"{line!r} is not in {source}"
    path = folder / (file or "keys.toml")
    path.write_text(text)
    path.chmod(0o600)
    return path


def _broken_cases() -> list:
    cases = []
    for name, file, line, new, field in BROKEN:
        for guess in (False, True):
            if guess and field == "kind":
                continue  # without its kind the file is a braking scenario, guessed as one
            how = "guessed" if guess else "as"
            cases.append(
                pytest.param(name, file, line, new, field, guess, id=f"{name}-{field}-{how}")
            )
    return cases


@pytest.mark.parametrize(("name", "file", "line", "new", "field", "guess"), _broken_cases())
def test_a_broken_copy_exits_2_naming_the_key(
    name, file, line, new, field, guess, capsys, tmp_path, monkeypatch
):
    path = broken_copy(tmp_path, name, file, line, new)
    monkeypatch.chdir(tmp_path)
    before = sorted(tmp_path.rglob("*"))
    args = [str(path)] + ([] if guess else ["--as", name])
    code, out, err = validate(capsys, *args)
    assert code == 2
    assert out == ""
    assert err.startswith("railpilot: error: ") and err.count("\n") == 1
    assert re.search(rf"(?<![A-Za-z_]){re.escape(field)}(?![A-Za-z_])", err), err
    assert sorted(tmp_path.rglob("*")) == before  # nothing written


def test_a_key_file_others_may_read_is_refused(capsys, tmp_path):
    path = key_file(tmp_path, mode=0o644)
    code, out, err = validate(capsys, str(path), "--as", "keys")
    assert (code, out) == (2, "")
    assert "chmod 600" in err


def test_a_timetable_is_checked_against_the_line_given(capsys):
    path = LINES / "heavy_haul_timetable.toml"
    code, out, err = validate(capsys, str(path), "--line", "metro")
    assert (code, out) == (2, "")
    assert "line metro" in err


def test_a_line_that_is_not_there_is_named_as_the_option(capsys):
    path = LINES / "heavy_haul_timetable.toml"
    code, out, err = validate(capsys, str(path), "--line", "nowhere")
    assert (code, out) == (2, "")
    assert "--line = 'nowhere'" in err


def test_a_file_that_is_not_toml_says_so(capsys, tmp_path):
    path = tmp_path / "x.toml"
    path.write_text("x = [\n")
    for args in ([str(path)], [str(path), "--as", "line-run"]):
        code, out, err = validate(capsys, *args)
        assert (code, out) == (2, "")
        assert "valid TOML" in err


def test_a_file_no_format_fits_names_what_was_looked_for(capsys, tmp_path):
    path = tmp_path / "x.toml"
    path.write_text("colour = 'red'\n")
    code, out, err = validate(capsys, str(path))
    assert (code, out) == (2, "")
    assert "--as" in err and "colour" in err and "services" in err
    assert all(name in err for name in FORMATS)


def test_an_unknown_format_is_refused(capsys):
    code, out, err = validate(capsys, str(EXAMPLES / "eddy_case1.toml"), "--as", "bogus")
    assert (code, out) == (2, "")
    assert "bogus" in err and "consist-library" in err
