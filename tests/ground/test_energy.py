"""Energy-time curves from the onboard planner (railpilot.ground.energy).

On the shipped heavy-haul line's first section (Shenchi South to Ningwu West, 22.5 km): the
curve starts at the planner's fastest run, lies on or below every sample, passes through
the planner's own answer at a running time asked for (checked by calling the planner
again, through ``railpilot drive``'s route), and is convex and non-increasing (its
constructor checks both).
"""

from __future__ import annotations

import numpy as np
import pytest

from railpilot.errors import ConfigError
from railpilot.ground.energy import route_energy, section_energy
from railpilot.line import UP, load_line
from railpilot.onboard.drive import DEFAULT_MARGIN_KMH, StationRoute, heavy_haul_loaded
from railpilot.onboard.mrsp import travelled_m
from railpilot.onboard.planner import fastest, plan
from railpilot.units import kmh_to_mps

LINE = load_line("heavy-haul")
PRESET = heavy_haul_loaded()


@pytest.fixture(scope="module")
def first_section():  # type: ignore[no-untyped-def]
    return section_energy(LINE, PRESET, 1, 2, extra_times_s=(1490.0,))


def planner_section(from_id: int, to_id: int):  # type: ignore[no-untyped-def]
    """The planner's section of the station pair, built again here as ``drive`` does."""
    a, b = LINE.station(from_id), LINE.station(to_id)
    dep, arr = a.stop_m(UP), b.stop_m(UP)
    route = StationRoute(
        LINE,
        PRESET,
        UP,
        dep,
        float(travelled_m(arr, UP, dep)),
        kmh_to_mps(DEFAULT_MARGIN_KMH),
        (),
        (),
        0.0,
    )
    return route.section_from(route.mrsp_at(0.0), 0.0, 0.0)[1]


def test_curve_starts_at_the_fastest_run(first_section) -> None:  # type: ignore[no-untyped-def]
    sec = planner_section(1, 2)
    quickest = fastest(PRESET.driving, sec)
    assert first_section.fastest_s == pytest.approx(quickest.running_time_s)
    assert first_section.curve.times_s[0] == pytest.approx(quickest.running_time_s)
    assert first_section.curve.energy_kwh[0] == pytest.approx(quickest.energy_net_kwh)
    assert first_section.length_m == pytest.approx(22_500.0, abs=1.0)


def test_curve_is_below_every_sample(first_section) -> None:  # type: ignore[no-untyped-def]
    s = first_section
    assert s.times_s.size == 8  # seven factors and the timetable's 1,490 s
    gap = s.energy_net_kwh - s.curve.energy_at(s.times_s)
    assert np.all(gap >= -1e-9)
    assert s.hull_gap_kwh == pytest.approx(float(np.max(gap)))
    slopes = np.diff(s.curve.energy_kwh) / np.diff(s.curve.times_s)
    assert np.all(slopes <= 0) and np.all(np.diff(slopes) >= 0)


def test_sampled_energy_is_the_planners(first_section) -> None:  # type: ignore[no-untyped-def]
    s = first_section
    i = int(np.argmin(np.abs(s.times_s - 1490.0)))
    assert s.times_s[i] == pytest.approx(1490.0, abs=0.1)  # the planner's time tolerance
    again = plan(PRESET.driving, planner_section(1, 2), 1490.0)
    assert s.energy_net_kwh[i] == pytest.approx(again.energy_net_kwh)
    assert again.energy_net_kwh == pytest.approx(
        again.energy_traction_kwh - again.energy_regenerated_kwh
    )


def test_route_energy_chains_station_pairs() -> None:
    curves = route_energy(LINE, PRESET, [1, 2, 3], factors=(1.0, 1.1), planned_running_s={})
    assert [(c.from_station, c.to_station) for c in curves] == [(1, 2), (2, 3)]
    assert all(c.times_s.size == 2 for c in curves)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"factors": (0.9,)}, "factors"),
        ({"factors": ()}, "factors"),
        ({"extra_times_s": (-5.0,)}, "extra_times_s"),
    ],
)
def test_bad_sampling_names_the_field(kwargs: dict[str, object], field: str) -> None:
    with pytest.raises(ConfigError) as err:
        section_energy(LINE, PRESET, 1, 2, **kwargs)  # type: ignore[arg-type]
    assert err.value.field == field


def test_route_needs_two_stations() -> None:
    with pytest.raises(ConfigError) as err:
        route_energy(LINE, PRESET, [1])
    assert err.value.field == "stations"


def test_same_station_is_refused() -> None:
    with pytest.raises(ConfigError) as err:
        section_energy(LINE, PRESET, 3, 3)
    assert err.value.field == "to_station"
