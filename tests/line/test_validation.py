"""Bad line files: every rule gives a LineError naming the entry (and its neighbour)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from railpilot.errors import ConfigError, LineError, RailpilotError
from railpilot.line import load_line, parse_line, read_line

from .helpers import dumps, tiny, write

Mutation = Callable[[dict[str, Any]], None]


def _error(tmp_path: Path, mutate: Mutation) -> str:
    data = tiny()
    mutate(data)
    path = write(tmp_path, data)
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(LineError) as info:
        read_line(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written
    message = str(info.value)
    assert message.startswith(f"{path}: "), message  # names the file
    return message


def test_the_tiny_line_is_valid():
    line = parse_line(dumps(tiny()))
    assert line.name == "tiny"
    assert line.length_m == 3000.0


def test_line_error_is_a_config_error_so_the_cli_exits_2():
    # cli.py maps every RailpilotError to exit code 2 ("bad input, nothing run or written")
    assert issubclass(LineError, ConfigError)
    assert issubclass(LineError, RailpilotError)


# ---------------------------------------------------------------- gradients


def _set(section: str, index: int, **values: Any) -> Mutation:
    def mutate(data: dict[str, Any]) -> None:
        data[section][index].update(values)

    return mutate


def test_gradient_start_must_be_below_end(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        data["gradients"] = [
            {"start_km": 10.0, "end_km": 12.4, "permille": 1.0},
            {"start_km": 12.4, "end_km": 11.9, "permille": 1.0},
            {"start_km": 11.9, "end_km": 13.0, "permille": 1.0},
        ]

    message = _error(tmp_path, mutate)
    assert "gradients[1] (km 12.400-11.900).end_km = 11.9" in message
    assert "start must be below end" in message


def test_overlapping_gradients_name_both_entries(tmp_path):
    message = _error(tmp_path, _set("gradients", 1, start_km=10.8))
    assert "gradients[1] (km 10.800-13.000).start_km = 10.8" in message
    assert "the end of gradients[0] (km 10.000-11.000)" in message
    assert "overlaps" in message


def test_a_gap_between_gradients_names_both_entries(tmp_path):
    message = _error(tmp_path, _set("gradients", 1, start_km=11.2))
    assert "gradients[1] (km 11.200-13.000).start_km = 11.2" in message
    assert "gradients[0] (km 10.000-11.000)" in message
    assert "gap km 11.000-11.200" in message


def test_unsorted_gradients_are_an_error(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        data["gradients"].reverse()

    message = _error(tmp_path, mutate)
    assert "gradients[0] (km 11.000-13.000)" in message  # the first entry no longer starts at 10


def test_unsorted_gradients_named_with_the_entry_before(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        data["gradients"] = [
            {"start_km": 10.0, "end_km": 11.0, "permille": 0.0},
            {"start_km": 12.0, "end_km": 13.0, "permille": 0.0},
            {"start_km": 11.0, "end_km": 12.0, "permille": 0.0},
        ]

    message = _error(tmp_path, mutate)
    assert "gradients[2] (km 11.000-12.000).start_km = 11.0" in message
    assert "gradients[1] (km 12.000-13.000)" in message
    assert "sorted" in message


@pytest.mark.parametrize(
    ("index", "values", "text"),
    [
        (0, {"start_km": 10.5}, "gradients[0] (km 10.500-11.000).start_km = 10.5"),
        (1, {"end_km": 12.5}, "gradients[1] (km 11.000-12.500).end_km = 12.5"),
        (1, {"end_km": 13.5}, "gradients[1] (km 11.000-13.500).end_km = 13.5"),
    ],
)
def test_gradients_must_cover_the_line_exactly(tmp_path, index, values, text):
    message = _error(tmp_path, _set("gradients", index, **values))
    assert text in message


@pytest.mark.parametrize("permille", [40.5, -41.0])
def test_gradient_out_of_range(tmp_path, permille):
    message = _error(tmp_path, _set("gradients", 1, permille=permille))
    assert f"gradients[1] (km 11.000-13.000).permille = {permille}" in message
    assert "-40 to +40 per mille" in message


def test_a_gradient_that_is_not_a_number(tmp_path):
    message = _error(tmp_path, _set("gradients", 0, permille="steep"))
    assert "gradients[0] (km 10.000-11.000).permille = 'steep'" in message
    assert "a finite number" in message


# ---------------------------------------------------------------- curves


def test_curve_radius_below_150_m(tmp_path):
    message = _error(tmp_path, _set("curves", 0, radius_m=120.0))
    assert "curves[0] (km 11.500-12.000).radius_m = 120.0" in message
    assert ">= 150 m" in message


def test_overlapping_curves_name_both(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        data["curves"].append({"start_km": 11.9, "end_km": 12.2, "radius_m": 800.0})

    message = _error(tmp_path, mutate)
    assert "curves[1] (km 11.900-12.200).start_km = 11.9" in message
    assert "curves[0] (km 11.500-12.000)" in message


def test_curve_outside_the_line(tmp_path):
    message = _error(tmp_path, _set("curves", 0, start_km=12.8, end_km=13.2))
    assert "curves[0] (km 12.800-13.200).end_km = 13.2" in message
    assert "inside the line, km 10.000-13.000" in message


# ---------------------------------------------------------------- speed limits


@pytest.mark.parametrize("kmh", [250.0, 3.0])
def test_speed_limit_out_of_range(tmp_path, kmh):
    message = _error(tmp_path, _set("speed_limits", 3, limit_kmh=kmh))
    assert f"speed_limits[3] (b, both, km 10.000-13.000).limit_kmh = {kmh}" in message
    assert "5 to 200 km/h" in message


def test_speed_limit_of_an_unknown_category(tmp_path):
    message = _error(tmp_path, _set("speed_limits", 3, category="passenger"))
    assert "speed_limits[3] (passenger, both, km 10.000-13.000).category = 'passenger'" in message
    assert "one of the line's categories: a, b" in message


def test_a_gap_in_one_direction_names_the_entries(tmp_path):
    message = _error(tmp_path, _set("speed_limits", 2, start_km=12.5))
    assert "speed_limits[2] (a, down, km 12.500-13.000).start_km = 12.5" in message
    assert "speed_limits[0] (a, both, km 10.000-12.000)" in message
    assert "going down" in message


def test_overlapping_limits_of_one_direction(tmp_path):
    # a "both" entry over km 12-13 overlaps the up-only one there
    def mutate(data: dict[str, Any]) -> None:
        data["speed_limits"][0]["end_km"] = 12.5

    message = _error(tmp_path, mutate)
    assert "speed_limits[1] (a, up, km 12.000-13.000).start_km = 12.0" in message
    assert "overlaps speed_limits[0] (a, both, km 10.000-12.500)" in message


def test_a_category_without_limits(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        data["categories"].append("c")

    message = _error(tmp_path, mutate)
    assert "speed_limits = 'c'" in message
    assert "category 'c'" in message


def test_bad_direction_word(tmp_path):
    message = _error(tmp_path, _set("speed_limits", 1, direction="north"))
    assert "speed_limits[1] (a, north, km 12.000-13.000).direction = 'north'" in message
    assert "one of both, up, down" in message


def test_bad_category_name(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        data["categories"] = ["a", "Freight Loaded"]

    message = _error(tmp_path, mutate)
    assert "categories[1] = 'Freight Loaded'" in message


# ---------------------------------------------------------------- stations


def test_station_outside_the_line(tmp_path):
    message = _error(tmp_path, _set("stations", 0, km=12.9, stop_up_km=12.9, stop_down_km=12.9))
    assert "stations[0] (id 1 'S', km 12.900).km = 12.9" in message
    assert "inside the line" in message


def test_stop_point_outside_the_loop(tmp_path):
    message = _error(tmp_path, _set("stations", 0, stop_up_km=12.8))
    assert "stations[0] (id 1 'S', km 12.500).stop_up_km = 12.8" in message
    assert "inside the station's loop, km 12.300-12.700" in message


def test_loop_length_out_of_range(tmp_path):
    message = _error(tmp_path, _set("stations", 0, loop_length_m=7000.0))
    assert "stations[0] (id 1 'S', km 12.500).loop_length_m = 7000.0" in message
    assert "20 to 6000 m" in message


def _second_station(**values: Any) -> Mutation:
    def mutate(data: dict[str, Any]) -> None:
        station = {"id": 2, "name": "T", "km": 11.0, "loop_length_m": 300.0}
        station.update(values)
        data["stations"].append(station)

    return mutate


def test_duplicate_station_id(tmp_path):
    message = _error(tmp_path, _second_station(id=1))
    assert "stations[1] (id 1 'T', km 11.000).id = 1" in message
    assert "not used by stations[0] (id 1 'S', km 12.500)" in message


def test_unsorted_stations(tmp_path):
    message = _error(tmp_path, _second_station())
    assert "stations[1] (id 2 'T', km 11.000).km = 11.0" in message
    assert "after stations[0] (id 1 'S', km 12.500)" in message


def test_overlapping_station_loops(tmp_path):
    message = _error(tmp_path, _second_station(km=12.8, loop_length_m=300.0))
    assert "stations[1] (id 2 'T', km 12.800).km = 12.8" in message
    assert "loop of stations[0] (id 1 'S', km 12.500) ends, km 12.700" in message


def test_station_id_must_be_an_integer(tmp_path):
    message = _error(tmp_path, _set("stations", 0, id="one"))
    assert "stations[0] (id 'one' 'S', km 12.500).id = 'one'" in message


# ---------------------------------------------------------------- signals


def test_duplicate_signal_id(tmp_path):
    message = _error(tmp_path, _set("signals", 2, id="U1"))
    assert "signals[2] ('U1', up, km 12.000).id = 'U1'" in message
    assert "not used by signals[0] ('U1', up, km 10.500)" in message


def test_signal_outside_the_line(tmp_path):
    message = _error(tmp_path, _set("signals", 5, km=13.4))
    assert "signals[5] ('D3', down, km 13.400).km = 13.4" in message


def test_unsorted_signals(tmp_path):
    message = _error(tmp_path, _set("signals", 2, km=10.2))
    assert "signals[2] ('U2', up, km 10.200).km = 10.2" in message
    assert "at or after signals[1] ('D1', down, km 11.000)" in message


def test_two_signals_of_one_direction_at_one_km_post(tmp_path):
    message = _error(tmp_path, _set("signals", 2, km=11.0, direction="down"))
    assert "signals[2] ('U2', down, km 11.000).km = 11.0" in message
    assert "signals[1] ('D1', down, km 11.000)" in message


def test_bad_signal_kind(tmp_path):
    message = _error(tmp_path, _set("signals", 0, kind="distant"))
    assert "signals[0] ('U1', up, km 10.500).kind = 'distant'" in message
    assert "one of home, exit, block" in message


# ---------------------------------------------------------------- block sections


def _blocks(*up: tuple[float, float], down: tuple[tuple[float, float], ...] = ()) -> Mutation:
    def mutate(data: dict[str, Any]) -> None:
        down_spans = down or ((10.0, 11.0), (11.0, 12.3), (12.3, 12.9), (12.9, 13.0))
        data["block_sections"] = [
            {"id": f"u{i}", "direction": "up", "start_km": a, "end_km": b}
            for i, (a, b) in enumerate(up)
        ] + [
            {"id": f"d{i}", "direction": "down", "start_km": a, "end_km": b}
            for i, (a, b) in enumerate(down_spans)
        ]

    return mutate


GOOD_UP = ((10.0, 10.5), (10.5, 12.0), (12.0, 12.7), (12.7, 13.0))


def test_given_block_sections_that_match_the_signals_load(tmp_path):
    data = tiny()
    _blocks(*GOOD_UP)(data)
    line = read_line(write(tmp_path, data))
    assert [s.entry_signal for s in line.block_sections] == [
        None, "U1", "U2", "U3", "D1", "D2", "D3", None
    ]  # fmt: skip


def test_a_gap_between_block_sections(tmp_path):
    message = _error(tmp_path, _blocks((10.0, 10.5), (10.5, 11.9), (12.0, 12.7), (12.7, 13.0)))
    assert "block_sections[2] ('u2', up, km 12.000-12.700).start_km = 12.0" in message
    assert "block_sections[1] ('u1', up, km 10.500-11.900)" in message


def test_a_block_section_not_beginning_at_a_signal(tmp_path):
    message = _error(tmp_path, _blocks((10.0, 10.5), (10.5, 11.5), (11.5, 12.7), (12.7, 13.0)))
    assert "block_sections[1] ('u1', up, km 10.500-11.500)" not in message
    assert "block_sections[2] ('u2', up, km 11.500-12.700).start_km = 11.5" in message
    assert "up signal" in message


def test_a_signal_protecting_no_block_section(tmp_path):
    message = _error(tmp_path, _blocks((10.0, 12.0), (12.0, 12.7), (12.7, 13.0)))
    assert "signals[0] ('U1', up, km 10.500).km = 10.5" in message
    assert "every signal protects a block section" in message


# ---------------------------------------------------------------- keys, types, files


def test_unknown_top_level_key_lists_the_allowed_ones(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        data["lenght_km"] = 3.0

    message = _error(tmp_path, mutate)
    assert "lenght_km = 3.0" in message
    assert "allowed here: name, description, start_km, end_km" in message


def test_unknown_key_in_an_entry(tmp_path):
    message = _error(tmp_path, _set("gradients", 1, slope=3.0))
    assert "gradients[1] (km 11.000-13.000).slope = 3.0" in message
    assert "allowed here: start_km, end_km, permille" in message


def test_missing_required_key(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        del data["speed_limits"][3]["limit_kmh"]

    message = _error(tmp_path, mutate)
    assert "speed_limits[3] (b, both, km 10.000-13.000).limit_kmh is missing" in message
    assert "required" in message


def test_end_before_start_of_the_line(tmp_path):
    def mutate(data: dict[str, Any]) -> None:
        data["end_km"] = 9.0

    message = _error(tmp_path, mutate)
    assert "end_km = 9.0" in message


def test_a_line_file_in_json_reads_as_the_same_line(tmp_path):
    path = tmp_path / "line.json"
    path.write_text(json.dumps({"$schema": "line.schema.json", **tiny()}), encoding="utf-8")
    assert read_line(path) == read_line(write(tmp_path, tiny()))


def test_a_key_of_the_wrong_type_is_named_with_what_is_allowed(tmp_path):
    message = _error(tmp_path, _set("signals", 0, direction=3))
    assert "signals[0] ('U1', 3, km 10.500).direction = 3" in message
    assert "a string (the key is required)" in message
    message = _error(tmp_path, _set("stations", 0, km=2e4))
    assert "stations[0].km = 20000.0" in message
    assert "a km post in [-10000, 10000]" in message


def test_invalid_toml(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("name = [unclosed\n", encoding="utf-8")
    with pytest.raises(LineError, match="valid TOML"):
        read_line(path)


def test_missing_file_and_unknown_name(tmp_path):
    with pytest.raises(LineError, match="an existing line TOML file"):
        read_line(tmp_path / "nope.toml")
    with pytest.raises(LineError, match=r"a shipped line \(heavy-haul, metro\)"):
        load_line("freight-only")
