"""``railpilot reproduce heavy-haul-ltd``: the consist against published heavy-haul figures
(docs/consist-run.md, "Published figures against the model")."""

from __future__ import annotations

import pytest

from railpilot.reproduce import heavy_haul_ltd

# the heavy-haul train's longitudinal dynamics, reproduced
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def reproduction(tmp_path_factory):
    return heavy_haul_ltd.run(tmp_path_factory.mktemp("ltd"))


def _metrics(reproduction, case):
    return reproduction.payload[case]["metrics"]


def test_its_figures_and_table_are_written(reproduction):
    assert all(path.is_file() for path in reproduction.figures)
    (table,) = reproduction.tables
    assert [row[0] for row in table.rows] == list(reproduction.payload)


def test_service_braking_stays_under_the_coupler_limit(reproduction):
    for case in ("service_10kt", "service_20kt_dp", "service_20kt_no_dp"):
        m = _metrics(reproduction, case)
        assert m["coupler_force_limit_exceeded_s"] == 0.0
        assert max(m["max_coupler_tension_kn"], m["max_coupler_compression_kn"]) < 2_250.0


def test_distributed_power_lowers_the_in_train_forces_and_the_delay_raises_them(reproduction):
    for label in ("service", "emergency"):
        with_dp = _metrics(reproduction, f"{label}_20kt_dp")
        without = _metrics(reproduction, f"{label}_20kt_no_dp")
        assert with_dp["max_coupler_compression_kn"] < without["max_coupler_compression_kn"]
    by_delay = [
        _metrics(reproduction, case)["max_coupler_compression_kn"]
        for case in ("emergency_20kt_delay_0s", "emergency_20kt_dp", "emergency_20kt_delay_3s")
    ]
    assert by_delay == sorted(by_delay)


def test_emergency_stops_are_within_the_rule_of_800_m(reproduction):
    for case in ("emergency_10kt", "emergency_20kt_dp", "emergency_20kt_no_dp"):
        m = _metrics(reproduction, case)
        assert m["emergency_speed_kmh"] == pytest.approx(80.0, abs=0.5)
        assert 0.0 < m["emergency_stopping_distance_m"] < 800.0
