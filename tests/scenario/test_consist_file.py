"""Consist files (railpilot.scenario.consist_file): the errors name the file, the vehicle and
the field; a file written from a consist reads back into it; the shipped presets agree with
the published Daqin trains."""

from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from railpilot.errors import ScenarioError
from railpilot.scenario.consist_file import (
    ConsistError,
    consist_preset,
    consist_to_toml,
    library_draft_gears,
    library_types,
    load_consist,
    parse_consist,
    write_consist,
)
from railpilot.units import G_MPS2
from railpilot.vehicle.consist import CONSIST_PRESETS, Consist, Vehicle
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.traction import HXD1_LENGTH_M, HXD1_MASS_KG, hxd1_locomotive

SOURCE = "my_train.toml"

#: a file with its own wagon type, locomotive type and draft gear, beside the library's
BASE: dict[str, Any] = {
    "name": "a user's train",
    "description": "a hopper of the user's own behind the library's C80",
    "brake_pipe_kpa": 500.0,
    "dp_radio_delay_s": 2.0,
    "draft_gears": {
        "G1": {
            "slack_mm": 25.0,
            "travel_mm": 150.0,
            "preload_kn": 50.0,
            "force_at_travel_kn": 1800.0,
            "unloading_ratio": 0.3,
            "stop_stiffness_kn_per_mm": 80.0,
            "damping_kn_s_per_m": 60.0,
            "switching_speed_mps": 0.02,
        }
    },
    "vehicle_types": {
        "HOP": {
            "kind": "wagon",
            "tare_t": 25.0,
            "payload_t": 95.0,
            "length_m": 14.0,
            "rotating_mass_t": 2.0,
            "distributor": "direct-release",
            "shoe_friction": 0.35,
            "draft_gear": "G1",
            "loaded": {"davis": [0.9, 0.005, 0.00012], "braking_ratio": 0.15},
            "empty": {"davis": [2.0, 0.006, 0.0007], "brake_force_kn": 30.0},
        },
        "LOCO": {
            "kind": "locomotive",
            "model": "HXD1",
            "mass_t": 184.0,
            "length_m": 35.222,
            "rotating_mass_factor": 0.08,
            "distributor": "graduated-release",
            "shoe_friction": 0.3,
            "davis": [2.25, 0.019, 0.00032],
            "braking_ratio": 0.2,
            "draft_gear": "MT-2",
        },
    },
    "train": [
        {"type": "LOCO", "count": 1},
        {"type": "HOP", "count": 3, "load": "loaded", "mass_t": 110.0, "draft_gear": "G1"},
        {"type": "C80", "count": 2, "load": "empty"},
        {"type": "HXD1", "count": 1},
        {"type": "HOP", "count": 2, "load": "empty"},
    ],
}


def parse(data: dict[str, Any]) -> Consist:
    return parse_consist(data, source=SOURCE)


def test_the_base_file_builds_the_train_it_says():
    consist = parse(BASE)
    names = [v.name for v in consist.vehicles]
    head = ["LOCO-1", "HOP-1", "HOP-2", "HOP-3", "C80-1", "C80-2", "HXD1-1"]
    assert names == [*head, "HOP-4", "HOP-5"]
    assert consist.brake_pipe_kpa == 500.0
    assert consist.dp_radio_delay_s == 2.0
    loco, hop_loaded, c80, hop_empty = (consist.vehicles[i] for i in (0, 1, 4, 8))
    # the locomotive: the model's envelopes at the file's mass and length
    assert loco.mass_kg == 184e3
    assert loco.locomotive is not None and loco.locomotive.mass_kg == 184e3
    assert loco.locomotive.traction == hxd1_locomotive().traction
    assert_allclose(loco.service_brake_force_n, 0.2 * 0.3 * 184e3 * G_MPS2, rtol=1e-12)
    # a block's mass_t replaces the load's: the braking ratio acts on it, the rotating mass
    # (a mass of the type) gives a factor at it
    assert hop_loaded.mass_kg == 110e3
    assert_allclose(hop_loaded.service_brake_force_n, 0.15 * 0.35 * 110e3 * G_MPS2, rtol=1e-12)
    assert_allclose(hop_loaded.rotating_mass_factor, 2.0 / 110.0, rtol=1e-12)
    assert hop_loaded.draft_gear.name == "G1"
    assert hop_empty.mass_kg == 25e3 and hop_empty.service_brake_force_n == 30e3
    assert (hop_empty.davis_a0, hop_empty.davis_a1, hop_empty.davis_a2) == (2.0, 0.006, 0.0007)
    assert c80.mass_kg == 20e3 and c80.draft_gear.name == "MT-2"
    # every locomotive after the first is a distributed-power remote
    assert [v.remote for v in consist.vehicles] == [False] * 6 + [True, False, False]


# --- one bad field: the error names the vehicle and the field ------------------------------

NUMBER_BAD = ["x", True, None, -1.0, 1e300, math.nan, [1.0, 2.0], {"a": 1}, 10**400]
CHOICE_BAD = ["x", "", 1.0, True, None, [1.0], {"a": 1}]
NAME_BAD = ["", 1.0, True, None, [1.0]]
TEXT_BAD = [1.0, True, None, ["a"]]
DAVIS_BAD = ["x", 1.0, True, None, [1.0, 2.0], [1.0, 2.0, "x"], [-1.0, 0.0, 0.0], [0.0, 1e300, 0.0]]


def _fields() -> list[tuple[tuple[Any, ...], str, list[Any]]]:
    """(path in BASE, the field an error must name, bad values) for every field of BASE."""
    fields: list[tuple[tuple[Any, ...], str, list[Any]]] = [
        (("name",), "name", NAME_BAD),
        (("description",), "description", TEXT_BAD),
        (("brake_pipe_kpa",), "brake_pipe_kpa", NUMBER_BAD),
        (("dp_radio_delay_s",), "dp_radio_delay_s", NUMBER_BAD),
    ]
    for key in BASE["draft_gears"]["G1"]:
        fields.append((("draft_gears", "G1", key), f"draft_gears.G1.{key}", NUMBER_BAD))
    choices = {"kind", "distributor", "draft_gear", "model"}
    for name, table in BASE["vehicle_types"].items():
        for key, value in table.items():
            label = f"vehicle_types.{name}.{key}"
            if isinstance(value, dict):
                for sub in value:
                    bad = DAVIS_BAD if sub == "davis" else NUMBER_BAD
                    fields.append((("vehicle_types", name, key, sub), f"{label}.{sub}", bad))
            else:
                bad = DAVIS_BAD if key == "davis" else CHOICE_BAD if key in choices else NUMBER_BAD
                fields.append((("vehicle_types", name, key), label, bad))
    for i, block in enumerate(BASE["train"]):
        label = f"train[{i}] ({block['type']} x {block['count']})"
        for key in block:
            bad = NUMBER_BAD if key in ("count", "mass_t") else CHOICE_BAD
            fields.append((("train", i, key), f"{label}.{key}", bad))
    return fields


FIELDS = _fields()


def _with(path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    data = copy.deepcopy(BASE)
    table: Any = data
    for part in path[:-1]:
        table = table[part]
    table[path[-1]] = value
    return data


def _check_names(exc: ConsistError, expected: str) -> None:
    assert str(exc).startswith(f"{SOURCE}: "), str(exc)
    assert exc.source == SOURCE
    if expected.startswith("train[") and expected.rsplit(".", 1)[1] in ("type", "count"):
        # a bad type or count changes the block's label: its place and the key stay
        place, key = expected.split(" ", 1)[0], expected.rsplit(".", 1)[1]
        assert exc.field.startswith(place) and exc.field.endswith(f".{key}"), exc.field
    else:
        assert exc.field == expected or exc.field.startswith(f"{expected}["), exc.field
    assert len(str(exc)) < 600, str(exc)


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_any_one_bad_field_gives_a_consist_error_naming_its_vehicle_and_field(data):
    path, expected, bad = data.draw(st.sampled_from(FIELDS), label="field")
    value = data.draw(st.sampled_from(bad), label="value")
    with pytest.raises(ConsistError) as info:
        parse(_with(path, value))
    _check_names(info.value, expected)
    assert isinstance(info.value, ScenarioError)


def test_every_field_is_tried_with_every_bad_value():
    """The property test samples; this runs the whole grid once (a few hundred parses)."""
    for path, expected, bad in FIELDS:
        for value in bad:
            with pytest.raises(ConsistError) as info:
                parse(_with(path, value))
            _check_names(info.value, expected)


@pytest.mark.parametrize(
    ("path", "label"),
    [
        ((), ""),
        (("draft_gears", "G1"), "draft_gears.G1."),
        (("vehicle_types", "HOP"), "vehicle_types.HOP."),
        (("vehicle_types", "HOP", "loaded"), "vehicle_types.HOP.loaded."),
        (("vehicle_types", "LOCO"), "vehicle_types.LOCO."),
        (("train", 2), "train[2] (C80 x 2)."),
    ],
)
def test_an_unknown_key_is_refused_by_name(path, label):
    data = copy.deepcopy(BASE)
    table: Any = data
    for part in path:
        table = table[part]
    table["mass_kg"] = 1.0
    with pytest.raises(ConsistError, match="known key") as info:
        parse(data)
    assert info.value.field == f"{label}mass_kg"


def test_a_wagon_type_takes_no_locomotive_key():
    data = _with(("vehicle_types", "HOP", "model"), "HXD1")
    with pytest.raises(ConsistError, match="known key"):
        parse(data)


# --- rules across fields --------------------------------------------------------------------


def _error(data: dict[str, Any]) -> ConsistError:
    with pytest.raises(ConsistError) as info:
        parse(data)
    return info.value


def test_the_first_vehicle_must_be_a_locomotive():
    data = copy.deepcopy(BASE)
    data["train"] = data["train"][1:]
    exc = _error(data)
    assert exc.field == "train[0] (HOP x 3).type"
    assert "lead locomotive" in exc.allowed


def test_a_train_needs_blocks():
    for train in (None, [], "HXD1"):
        assert _error(_with(("train",), train)).field == "train"


def test_loads_belong_to_wagons_and_every_wagon_block_gives_one():
    assert _error(_with(("train", 0, "load"), "loaded")).field == "train[0] (LOCO x 1).load"
    data = copy.deepcopy(BASE)
    del data["train"][2]["load"]
    assert _error(data).field == "train[2] (C80 x 2).load"


def test_a_brake_is_given_once_with_what_it_needs():
    both = _with(("vehicle_types", "HOP", "empty", "braking_ratio"), 0.2)
    assert _error(both).field == "vehicle_types.HOP.empty.braking_ratio"
    data = copy.deepcopy(BASE)
    del data["vehicle_types"]["HOP"]["shoe_friction"]
    assert _error(data).field == "vehicle_types.HOP.loaded.braking_ratio"
    data = copy.deepcopy(BASE)
    del data["vehicle_types"]["HOP"]["empty"]["brake_force_kn"]
    assert _error(data).field == "vehicle_types.HOP.empty.brake_force_kn"
    no_air = _with(("vehicle_types", "LOCO", "distributor"), "none")
    assert _error(no_air).field == "vehicle_types.LOCO.braking_ratio"


def test_exactly_one_rotating_mass():
    both = _with(("vehicle_types", "HOP", "rotating_mass_factor"), 0.02)
    assert _error(both).field == "vehicle_types.HOP.rotating_mass_t"
    data = copy.deepcopy(BASE)
    del data["vehicle_types"]["HOP"]["rotating_mass_t"]
    assert _error(data).field == "vehicle_types.HOP.rotating_mass_t"


def test_a_block_mass_that_makes_a_vehicle_impossible_is_named_in_the_block():
    # 2 t of rotating mass on a 0.1 t wagon: gamma 20, beyond the model's bound
    exc = _error(_with(("train", 1, "mass_t"), 0.1))
    assert exc.field == "train[1] (HOP x 3).rotating_mass_factor"


def test_the_train_is_at_most_max_length_long():
    exc = _error(_with(("train", 2, "count"), 850))  # 850 x 12 m + the rest > 10 km
    assert exc.field == "train"
    assert "10000 m" in exc.allowed


def test_a_file_type_replaces_the_library_s_under_its_name():
    data = copy.deepcopy(BASE)
    data["vehicle_types"]["C80"] = copy.deepcopy(data["vehicle_types"]["HOP"])
    consist = parse(data)
    assert consist.vehicles[4].name == "C80-1" and consist.vehicles[4].mass_kg == 25e3


def test_the_library_holds_the_c80_the_hxd1_and_the_mt2():
    assert {"C80", "HXD1"} <= set(library_types())
    assert "MT-2" in library_draft_gears()


# --- files ----------------------------------------------------------------------------------


def test_a_missing_or_broken_file_is_a_consist_error_naming_it(tmp_path: Path):
    with pytest.raises(ConsistError, match="existing consist TOML file"):
        load_consist(tmp_path / "nothing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("name = \n", encoding="utf-8")
    with pytest.raises(ConsistError, match="valid TOML") as info:
        load_consist(broken)
    assert str(broken) in str(info.value)
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[[train]]\ntype = "C80"\ncount = 2\nload = "full"\n', "utf-8")
    with pytest.raises(ConsistError) as info:
        load_consist(bad)
    assert str(info.value).startswith(f"{bad}: train[0] (C80 x 2).load = 'full'")


def _assert_same(a: Consist, b: Consist) -> None:
    """Equal but for masses and forces, which pass through t and kN (1 ulp)."""
    assert (a.name, a.n_vehicles) == (b.name, b.n_vehicles)
    assert [v.name for v in a.vehicles] == [v.name for v in b.vehicles]
    for x, y in zip(a.vehicles, b.vehicles, strict=True):
        for field in ("kind", "distributor", "remote"):
            assert getattr(x, field) == getattr(y, field)
        for field in ("mass_kg", "rotating_mass_factor", "length_m", "service_brake_force_n"):
            assert_allclose(getattr(x, field), getattr(y, field), rtol=1e-14)
        assert_allclose(
            [x.davis_a0, x.davis_a1, x.davis_a2], [y.davis_a0, y.davis_a1, y.davis_a2], rtol=0
        )
        for field in ("slack_m", "travel_m", "preload_n", "force_at_travel_n"):
            assert_allclose(getattr(x.draft_gear, field), getattr(y.draft_gear, field), rtol=1e-14)
        assert (x.locomotive is None) == (y.locomotive is None)
        if x.locomotive is not None and y.locomotive is not None:
            assert x.locomotive.traction == y.locomotive.traction
            assert x.locomotive.regen == y.locomotive.regen
    assert (a.brake_pipe_kpa, a.dp_radio_delay_s) == (b.brake_pipe_kpa, b.dp_radio_delay_s)


@pytest.mark.parametrize("name", CONSIST_PRESETS)
def test_a_written_preset_reads_back_as_itself(name: str, tmp_path: Path):
    consist = consist_preset(name)
    path = tmp_path / "written.toml"
    write_consist(consist, path)
    _assert_same(load_consist(path), consist)


def test_the_base_file_round_trips_through_its_written_form(tmp_path: Path):
    consist = parse(BASE)
    path = tmp_path / "base.toml"
    path.write_text(consist_to_toml(consist), encoding="utf-8")
    again = load_consist(path)
    _assert_same(again, consist)
    # and a second round is exact: the written file is a fixed point
    assert consist_to_toml(again) == consist_to_toml(load_consist(path))


_GEARS = [
    DraftGear("A", 0.0095, 0.166, 1e5, 2.27e6, 0.2, 1e8, 1e5),
    DraftGear("B", 0.025, 0.15, 5e4, 1.8e6, 0.3, 8e7, 6e4, 0.02),
]


@st.composite
def consists(draw: st.DrawFn) -> Consist:
    loco = hxd1_locomotive()
    n = draw(st.integers(1, 30))
    remote_at = draw(st.none() | st.integers(1, n))
    vehicles: list[Vehicle] = []
    counts = {"L": 0, "W": 0}
    widths = {"L": 1, "W": len(str(n))}

    def named(prefix: str) -> str:  # the reader's names: PREFIX-k, zero-padded
        counts[prefix] += 1
        return f"{prefix}-{counts[prefix]:0{widths[prefix]}d}"

    for i in range(n + 1 + (remote_at is not None)):
        is_loco = i == 0 or (remote_at is not None and i == remote_at + 1)
        brake = draw(st.floats(1e3, 3e5))
        distributor = draw(st.sampled_from(["direct-release", "graduated-release", "none"]))
        fields: dict[str, Any] = {
            "mass_kg": draw(st.floats(1e4, 3e5)),
            "rotating_mass_factor": draw(st.floats(0.0, 0.3)),
            "length_m": draw(st.floats(5.0, 40.0)),
            "davis_a0": draw(st.floats(0.0, 3.0)),
            "davis_a1": draw(st.floats(0.0, 0.03)),
            "davis_a2": draw(st.floats(0.0, 0.001)),
            "service_brake_force_n": 0.0 if distributor == "none" else brake,
            "distributor": distributor,
            "draft_gear": draw(st.sampled_from(_GEARS)),
        }
        if is_loco:
            fields["locomotive"] = dataclasses.replace(
                loco, mass_kg=fields["mass_kg"], length_m=fields["length_m"]
            )
            vehicles.append(Vehicle(named("L"), "locomotive", remote=i > 0, **fields))
        else:
            vehicles.append(Vehicle(named("W"), "wagon", **fields))
    return Consist(
        draw(st.sampled_from(["x", "a train", "Zug 1"])),
        tuple(vehicles),
        brake_pipe_kpa=draw(st.floats(300.0, 800.0)),
        dp_radio_delay_s=draw(st.floats(0.0, 5.0)),
    )


@settings(max_examples=60, deadline=None)
@given(consist=consists())
def test_any_consist_round_trips_through_a_file(consist: Consist):
    text = consist_to_toml(consist)
    _assert_same(parse_consist(tomllib.loads(text), "round trip"), consist)


# --- the presets against the published trains ----------------------------------------------

#: published: the Daqin 20,000 t combined train is 210 C80 and two HXD1, about 2,614.3 m
#: long, carrying 16,800 t of coal (docs/consist.md: nihao-ac.tk; caodingtushuguan.com;
#: Xinhua "over 2.5 km", "2.6 km")
DAQIN_20KT_LENGTH_M = 2614.3
DAQIN_20KT_COAL_T = 16_800.0
#: published: C80 length 12,000 mm, 80 t load, tare under 20 t, 25 t axle load (4 axles)
C80_LENGTH_M, C80_PAYLOAD_T, C80_AXLE_LOAD_T = 12.0, 80.0, 25.0


def _wagons(consist: Consist) -> list[Vehicle]:
    return [v for v in consist.vehicles if v.kind == "wagon"]


def test_the_20kt_preset_is_the_published_daqin_combined_train():
    consist = consist_preset("heavy-haul-20kt-dp")
    wagons = _wagons(consist)
    assert len(wagons) == 210 and consist.locomotive_indices().size == 2
    # gross wagon mass: the published axle load on four axles; the coal: published
    assert all(w.mass_kg == 4 * C80_AXLE_LOAD_T * 1000.0 for w in wagons)
    payload_t = sum(w.mass_kg for w in wagons) / 1000.0 - 210 * (
        4 * C80_AXLE_LOAD_T - C80_PAYLOAD_T
    )
    assert payload_t == DAQIN_20KT_COAL_T
    # total: 21,000 t of wagons and two 200 t HXD1 (published masses)
    assert consist.mass_kg == 210 * 100e3 + 2 * HXD1_MASS_KG
    # length: 210 x 12.000 m + 2 x 35.222 m = 2,590.4 m against the published 2,614.3 m:
    # 0.9 % short; the sources quote the length as "about" (and "over 2.5 km", "2.6 km")
    assert consist.length_m == pytest.approx(210 * C80_LENGTH_M + 2 * HXD1_LENGTH_M)
    assert consist.length_m == pytest.approx(DAQIN_20KT_LENGTH_M, rel=0.01)


def test_the_10kt_presets_are_half_the_combined_train():
    loaded = consist_preset("heavy-haul-10kt")
    empty = consist_preset("heavy-haul-10kt-empty")
    for consist in (loaded, empty):
        assert len(_wagons(consist)) == 105 and consist.locomotive_indices().tolist() == [0]
        assert consist.remote_indices().size == 0
        assert consist.length_m == pytest.approx(DAQIN_20KT_LENGTH_M / 2, rel=0.015)
    # loaded: 105 x 100 t + 200 t; empty: the tare, "under 20 t", taken at 20 t
    assert loaded.mass_kg == 105 * 100e3 + HXD1_MASS_KG
    assert empty.mass_kg == 105 * 20e3 + HXD1_MASS_KG
    # the trailing load is the "10,000 t class": 10,500 t
    assert sum(w.mass_kg for w in _wagons(loaded)) == 10_500e3


def test_the_presets_point_mass_trains_by_hand():
    loaded = consist_preset("heavy-haul-10kt").point_mass_train()
    # 105 C80 at 100 t with Davis 0.92 + 0.0048 V + 0.000125 V^2 and one 200 t HXD1 at
    # 2.25 + 0.019 V + 0.00032 V^2 (TB/T 1407), weighed by mass
    m_w, m_l = 105 * 100.0, 200.0
    for got, wagon_k, loco_k in zip(
        (loaded.davis_a0, loaded.davis_a1, loaded.davis_a2),
        (0.92, 0.0048, 0.000125),
        (2.25, 0.019, 0.00032),
        strict=True,
    ):
        assert_allclose(got, (m_w * wagon_k + m_l * loco_k) / (m_w + m_l), rtol=1e-12)
    # brake: 0.18 braking ratio x 0.30 shoe friction x 100 t x g on each wagon, none on the
    # locomotive; over the effective mass (rotating 1.7 t a wagon, 13 t the locomotive)
    force = 105 * 0.18 * 0.30 * 100e3 * G_MPS2
    m_eff = 105 * (100e3 + 1.7e3) + 200e3 + 13e3
    assert_allclose(loaded.max_service_decel_mps2, force / m_eff, rtol=1e-12)
    assert loaded.max_service_decel_mps2 == pytest.approx(0.51, abs=0.005)
    # the empty train: 0.30 x 0.30 x 20 t x g a wagon
    empty = consist_preset("heavy-haul-10kt-empty").point_mass_train()
    m_eff = 105 * (20e3 + 1.7e3) + 200e3 + 13e3
    assert_allclose(
        empty.max_service_decel_mps2, 105 * 0.30 * 0.30 * 20e3 * G_MPS2 / m_eff, rtol=1e-12
    )
    assert np.isclose(empty.rotating_mass_factor, (105 * 1.7 + 13.0) / 2300.0, rtol=1e-12)
