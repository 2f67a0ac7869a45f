"""Inputs checked against each other (railpilot.schema.cross_checks and its readers): km
posts on the line, stations of the line, running times the train can run, a line file
found beside the file that names it, a cap on a line run's trains, errors said once, an
output folder that exists, and a run cut short printing what it means."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from railpilot.cli import main
from railpilot.cosim.scenario import check_timetable, line_scenario_from_mapping
from railpilot.errors import ConfigError
from railpilot.line import load_line
from railpilot.line.loader import SHIPPED_LINES
from railpilot.onboard.drive import station_route, train_preset
from railpilot.onboard.planner import fastest
from railpilot.onboard.timetable import TimetableSection
from railpilot.schema.line_run import MAX_LINE_RUN_TRAINS

ROOT = Path(__file__).resolve().parents[2]
LINE = load_line("heavy-haul")
LINE_END_KM = LINE.end_m / 1000.0
STATION_IDS = [s.id for s in LINE.stations]
SHIPPED_LINE_FILE = ROOT / "src" / "railpilot" / "line" / "data" / SHIPPED_LINES["heavy-haul"]
LOADED = "heavy-haul-loaded"
MARGIN_KMH = 5.0

#: one loaded train on the line's first section
BASE: dict[str, Any] = {
    "name": "cross-checks",
    "line": "heavy-haul",
    "duration_h": 1.0,
    "services": [
        {"kind": "loaded", "from": 1, "to": 2, "first_departure_min": 1.0, "first_id": 101}
    ],
}
TSR = {
    "at_min": 5.0,
    "op": "tsr_set",
    "start_km": 10.0,
    "end_km": 12.0,
    "limit_kmh": 40,
    "valid_until_min": 30,
    "reason": "track work",
}
QUICK = settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
#: km posts beyond the line's last one (the heavy-haul line starts at km 0, and a file's
#: km posts are >= 0)
BEYOND_END_KM = st.floats(LINE_END_KM + 0.001, 5 * LINE_END_KM, allow_nan=False)


def write(path: Path, data: dict[str, Any]) -> Path:
    """``data`` as a TOML file (the few shapes these tests write)."""

    def value(v: Any) -> str:
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        return repr(v)

    lines = [f"{k} = {value(v)}" for k, v in data.items() if not isinstance(v, list | dict)]
    for key, v in data.items():
        if isinstance(v, dict):
            lines += [f"[{key}]", *(f"{k} = {value(x)}" for k, x in v.items())]
    for key, v in data.items():
        if isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines += [f"[[{key}]]", *(f"{k} = {value(x)}" for k, x in item.items())]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def the_fastest_s(from_id: int, to_id: int) -> float:
    """The loaded train's fastest run of a section, from the planner directly."""
    preset = train_preset(LOADED)
    route = station_route(LINE, preset, from_id, to_id, MARGIN_KMH, (), (), 0.0)
    _, grid = route.section_from(route.mrsp_at(0.0), 0.0, 0.0)
    return float(fastest(preset.driving, grid).running_time_s)


# ---------------------------------------------------------------- 1. on the line


@QUICK
@given(start_km=BEYOND_END_KM, length_km=st.floats(0.1, 20.0))
def test_a_dead_zone_beyond_the_line_is_refused(start_km: float, length_km: float) -> None:
    zone = {"start_km": start_km, "end_km": start_km + length_km}
    with pytest.raises(ConfigError) as caught:
        line_scenario_from_mapping(BASE | {"channel": {"dead_zones": [zone]}})
    assert caught.value.field == "channel.dead_zones[0].start_km"
    assert caught.value.value == start_km
    assert f"0 to {LINE_END_KM:g}" in caught.value.allowed


@QUICK
@given(end_km=BEYOND_END_KM)
def test_a_dead_zone_running_off_the_line_names_its_end(end_km: float) -> None:
    zone = {"start_km": LINE_END_KM - 1.0, "end_km": end_km}
    with pytest.raises(ConfigError) as caught:
        line_scenario_from_mapping(BASE | {"channel": {"dead_zones": [zone]}})
    assert caught.value.field == "channel.dead_zones[0].end_km"


def test_a_dead_zone_on_the_line_is_taken() -> None:
    zone = {"start_km": 0.0, "end_km": LINE_END_KM}
    scenario = line_scenario_from_mapping(BASE | {"channel": {"dead_zones": [zone]}})
    assert len(scenario.channel.dead_zones) == 1


@QUICK
@given(
    km=BEYOND_END_KM,
    event=st.sampled_from(
        [
            (TSR, "start_km"),
            (TSR | {"start_km": 1.0}, "end_km"),
            ({"at_min": 5.0, "op": "target", "trains": [101]}, "km"),
            ({"at_min": 5.0, "op": "restriction_set", "reason": "section_fault"}, "start_km"),
        ]
    ),
)
def test_events_beyond_the_line_are_refused_once_from_a_file(
    tmp_path_factory: pytest.TempPathFactory, km: float, event: tuple[dict[str, Any], str]
) -> None:
    """From a file, as a user meets them: the field, its value, the line's km posts, and
    what is allowed said once."""
    fields, key = event
    if fields["op"] == "restriction_set":
        fields = fields | {"end_km": km + 1.0}
    path = tmp_path_factory.mktemp("day") / "day.toml"
    write(path, BASE | {"events": [fields | {key: km}]})
    from railpilot.cosim.scenario import load_line_scenario

    with pytest.raises(ConfigError) as caught:
        load_line_scenario(path)
    message = str(caught.value)
    assert message.startswith(f"day.toml: events[0].{key}")
    assert f"on line heavy-haul, 0 to {LINE_END_KM:g}" in message
    assert message.count("is not allowed") == 1
    assert message.count("expected") == 1


# ------------------------------------------------- 2. running times the train can run


def timetable_file(tmp_path: Path, *sections: tuple[int, int, float]) -> Path:
    rows = [{"from": a, "to": b, "running_time_s": t} for a, b, t in sections]
    return write(tmp_path / "timetable.toml", {"name": "mine", "sections": rows})


def drive_args(timetable: Path, out: Path, to: int) -> list[str]:
    return [
        "drive",
        "heavy-haul",
        "--train",
        LOADED,
        "--from",
        "1",
        "--to",
        str(to),
        "--model",
        "point-mass",
        "--timetable",
        str(timetable),
        "--out",
        str(out),
        "--json",
    ]


def test_a_running_time_below_the_fastest_run_is_refused_before_the_drive(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    quickest = the_fastest_s(1, 2)
    path = timetable_file(tmp_path, (1, 2, 60.0))
    assert main(drive_args(path, tmp_path / "out", 2)) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert not (tmp_path / "out").exists()
    assert "section 1 -> 2" not in captured.err  # nothing was driven
    assert "sections[0].running_time_s = 60.0 is not allowed" in captured.err
    said = re.search(r"at least ([0-9.]+) s", captured.err)
    assert said is not None
    assert float(said.group(1)) == pytest.approx(quickest, abs=0.1)


@settings(max_examples=30, deadline=None)
@given(share=st.floats(0.05, 2.0))
def test_a_running_time_is_refused_exactly_below_the_fastest_run(share: float) -> None:
    quickest = the_fastest_s(2, 3)
    section = TimetableSection(2, 3, quickest * share)
    if share < 1.0:
        with pytest.raises(ConfigError) as caught:
            check_timetable((section,), LINE, LOADED, MARGIN_KMH)
        assert caught.value.field == "sections[0].running_time_s"
    else:
        check_timetable((section,), LINE, LOADED, MARGIN_KMH)


def test_only_the_sections_driven_are_held_to_the_fastest_run() -> None:
    too_fast = TimetableSection(2, 3, 1.0)
    sections = (TimetableSection(1, 2, 2.0 * the_fastest_s(1, 2)), too_fast)
    check_timetable(sections, LINE, LOADED, MARGIN_KMH, driven=(1, 2))
    with pytest.raises(ConfigError, match=r"sections\[1\].running_time_s"):
        check_timetable(sections, LINE, LOADED, MARGIN_KMH, driven=(1, 3))


# ----------------------------------------------- 3. a line file beside its line-run file


def test_a_line_file_is_found_beside_the_line_run_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "runs"
    folder.mkdir()
    shutil.copy(SHIPPED_LINE_FILE, folder / "my_line.toml")
    path = write(folder / "day.toml", BASE | {"line": "my_line.toml"})
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    from railpilot.cosim.scenario import load_line_scenario

    scenario = load_line_scenario(path)
    assert scenario.line == LINE


def test_a_line_file_that_is_not_there_names_the_key_and_where_it_was_looked_for(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "runs"
    folder.mkdir()
    path = write(folder / "day.toml", BASE | {"line": "my_line.toml"})
    # a file of that name in the working directory is not the one meant
    shutil.copy(SHIPPED_LINE_FILE, tmp_path / "my_line.toml")
    monkeypatch.chdir(tmp_path)
    from railpilot.cosim.scenario import load_line_scenario

    with pytest.raises(ConfigError) as caught:
        load_line_scenario(path)
    assert caught.value.field == "day.toml: line"
    assert str(folder / "my_line.toml") in caught.value.allowed


# ------------------------------------------------------------- 4. said once, not nested


@QUICK
@given(
    field_value=st.sampled_from(
        [
            ("limit_kmh", -5),
            ("limit_kmh", "fast"),
            ("valid_until_min", -1.0),
            ("start_km", -3.0),
            ("reason", 7),
        ]
    )
)
def test_a_bad_event_from_a_file_says_what_is_wrong_once(
    tmp_path_factory: pytest.TempPathFactory, field_value: tuple[str, Any]
) -> None:
    name, bad = field_value
    path = write(
        tmp_path_factory.mktemp("day") / "day.toml", BASE | {"events": [TSR | {name: bad}]}
    )
    from railpilot.cosim.scenario import load_line_scenario

    with pytest.raises(ConfigError) as caught:
        load_line_scenario(path)
    message = str(caught.value)
    assert message.startswith(f"day.toml: events[0].{name}")
    assert message.count("is not allowed") == 1


def test_an_error_in_the_line_file_keeps_the_line_files_name(tmp_path: Path) -> None:
    text = SHIPPED_LINE_FILE.read_text(encoding="utf-8")
    broken = text.replace('name = "heavy-haul"', 'name = "heavy-haul"\nlength = 1', 1)
    assert broken != text
    line_file = tmp_path / "my_line.toml"
    line_file.write_text(broken, encoding="utf-8")
    path = write(tmp_path / "day.toml", BASE | {"line": str(line_file)})
    from railpilot.cosim.scenario import load_line_scenario

    with pytest.raises(ConfigError) as caught:
        load_line_scenario(path)
    message = str(caught.value)
    assert message.startswith("day.toml: ")
    assert f"{line_file}: length = 1 is not allowed" in message
    assert message.count("is not allowed") == 1


# ------------------------------------------------------------ 5. an unknown station


def test_an_unknown_station_in_a_timetable_is_named_with_the_lines_ids(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    unknown = max(STATION_IDS) + 79
    path = timetable_file(tmp_path, (1, unknown, 1600.0), (unknown, 3, 1600.0))
    assert main(drive_args(path, tmp_path / "out", 3)) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and not (tmp_path / "out").exists()
    assert f"sections[0].to = {unknown} is not allowed" in captured.err
    assert ", ".join(str(i) for i in STATION_IDS) in captured.err
    assert "section 1 ->" not in captured.err  # refused before the first section ran


@QUICK
@given(station=st.integers(0, 10_000).filter(lambda i: i not in STATION_IDS))
def test_any_station_the_line_lacks_is_refused(station: int) -> None:
    with pytest.raises(ConfigError) as caught:
        line_scenario_from_mapping(BASE | {"services": [BASE["services"][0] | {"to": station}]})
    assert caught.value.field == "services[0].to"
    assert caught.value.allowed.endswith(", ".join(str(i) for i in STATION_IDS))
    with pytest.raises(ConfigError) as caught:
        check_timetable((TimetableSection(station, 1, 100.0),), LINE, LOADED, MARGIN_KMH)
    assert caught.value.field == "sections[0].from"


# ------------------------------------------------------------------ 6. --screenshot


def test_a_screenshot_into_a_missing_folder_is_refused_before_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import railpilot.cosim.live as live

    started: list[object] = []
    monkeypatch.setattr(live, "run_live", lambda *args, **kwargs: started.append(args))
    shot = tmp_path / "missing" / "dashboard.png"
    scenario = ROOT / "examples" / "line_live_short.toml"
    assert main(["line", "run", str(scenario), "--screenshot", str(shot)]) == 2
    assert started == []
    err = capsys.readouterr().err
    assert f"--screenshot = '{shot}' is not allowed" in err
    assert str(shot.parent) in err


# --------------------------------------------------------------- 7. a cap on trains


@pytest.mark.parametrize("split", [(MAX_LINE_RUN_TRAINS + 1,), (1000, MAX_LINE_RUN_TRAINS - 999)])
def test_more_trains_than_the_cap_are_refused(split: tuple[int, ...]) -> None:
    services = []
    first_id = 2
    for count in split:
        while count:
            n = min(count, 1000)  # a service's own count is at most 1000
            services.append(
                {
                    "kind": "loaded",
                    "from": 1,
                    "to": 2,
                    "first_departure_min": 0.0,
                    "every_min": 10.0,
                    "count": n,
                    "first_id": first_id,
                }
            )
            first_id += n
            count -= n
    with pytest.raises(ConfigError) as caught:
        line_scenario_from_mapping(BASE | {"duration_h": 168.0, "services": services})
    assert caught.value.field == "services"
    assert caught.value.value == MAX_LINE_RUN_TRAINS + 1
    assert f"at most {MAX_LINE_RUN_TRAINS} trains" in caught.value.allowed


def test_the_cap_is_documented() -> None:
    docs = (ROOT / "docs" / "file-formats.md").read_text(encoding="utf-8")
    assert f"at most {MAX_LINE_RUN_TRAINS:,} trains" in docs


# ------------------------------------------------------- 8. a run cut short, no None


def test_a_run_cut_short_prints_what_it_means_not_none(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # the train departs at 1 min and the run ends at 6: it cannot arrive
    cut = BASE | {"duration_h": 0.1}
    path = write(tmp_path / "cut.toml", cut)
    assert main(["line", "simulate", str(path), "--no-baseline"]) == 0
    out = capsys.readouterr().out
    assert "None" not in out
    assert "no train arrived" in out
