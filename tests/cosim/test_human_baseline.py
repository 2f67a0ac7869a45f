"""The human-driver baseline (cosim/human_driver.py, its hook in cosim/driver.py, the
KPI object's baselines in cosim/kpis.py, ``line simulate --baselines``).

The driver's profile is checked on synthetic sections where its rules have one answer
(a level run, a descent the regenerative brake cannot hold, one it can); its line runs
from the trackside (nothing unsafe, every train arrives, the same seed the same numbers);
its reaction time against a twin driver told nothing.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from railpilot.cli import main
from railpilot.commands.line import BASELINE_NAMES
from railpilot.cosim.driver import BASELINES, DRIVERS
from railpilot.cosim.human_driver import DEFAULT_HUMAN, HumanDriving, human_curve
from railpilot.cosim.line_run import line_train, run_line
from railpilot.cosim.scenario import line_scenario_from_mapping
from railpilot.errors import ConfigError
from railpilot.link.events import TsrApplied
from railpilot.link.messages import TravelDirection, TsrSet
from railpilot.onboard.drive import heavy_haul_loaded
from railpilot.onboard.mrsp import apply_tsr
from railpilot.onboard.planner import SectionGrid
from railpilot.units import kmh_to_mps

from .test_line_cli import TINY
from .test_line_run import BASE

TRAIN = heavy_haul_loaded().driving
#: a ceiling of 75 km/h (80 km/h less the planner's 5 km/h margin)
PLANNED_MARGIN_MPS = kmh_to_mps(5.0)
CEILING_MPS = kmh_to_mps(75.0)
DX_M = 10.0
#: float noise [m/s]
TOL_MPS = 1e-9


def _grid(length_m: float, line_w: float) -> SectionGrid:
    """A section of one gradient ``line_w`` [N/kN, negative: a descent] under one limit,
    from rest to a stop."""
    s = np.arange(0.0, length_m + DX_M / 2, DX_M)
    ceiling = np.full(s.size, CEILING_MPS)
    ceiling[0] = ceiling[-1] = 0.0
    return SectionGrid(s, ceiling, np.full(s.size, float(line_w)), DX_M)


def _curve(sec: SectionGrid, human: HumanDriving = DEFAULT_HUMAN) -> np.ndarray:
    return human_curve(TRAIN, sec, human, planned_margin_mps=PLANNED_MARGIN_MPS).speed_mps


def _apply_mps(human: HumanDriving = DEFAULT_HUMAN) -> float:
    """The speed the driver holds: the limit less its margin."""
    return CEILING_MPS + PLANNED_MARGIN_MPS - kmh_to_mps(human.margin_kmh)


def _regen_cannot_hold_w() -> float:
    """A descent [N/kN] steeper than the regenerative brake's full force holds at the
    apply speed (the train's own resistance helping)."""
    t = TRAIN.train
    regen = TRAIN.locomotive.regen.max_force_n
    hold = (regen + TRAIN.resistance_n(_apply_mps())) / (t.mass_kg * 9.8 / 1000.0)
    return -(hold + 3.0)


# ------------------------------------------------------------------ the driver's profile


def test_it_holds_its_margin_under_the_limit_and_stops_at_the_end():
    for w in (0.0, -3.0, _regen_cannot_hold_w(), 4.0):
        v = _curve(_grid(20_000.0, w))
        assert v[0] == 0.0 and v[-1] == 0.0
        assert np.all(v[1:-1] > 0.0), w  # it never stands before the stop
        assert v.max() <= _apply_mps() + TOL_MPS, w


def test_on_the_level_it_shuts_off_power_a_fixed_distance_before_braking():
    v = _curve(_grid(20_000.0, 0.0))
    no_coast = _curve(
        _grid(20_000.0, 0.0), dataclasses.replace(DEFAULT_HUMAN, coast_before_brake_m=0)
    )
    shut_off = int(np.flatnonzero(v >= _apply_mps() - TOL_MPS)[-1])  # last at its speed
    braking_starts = int(np.flatnonzero(np.diff(no_coast) < 0.0)[0])
    coast_cells = round(DEFAULT_HUMAN.coast_before_brake_m / DX_M)
    assert braking_starts - shut_off == pytest.approx(coast_cells, abs=1)
    # from there to the stop it only slows, coasting until the braking curve meets it
    assert np.all(np.diff(v[shut_off:]) <= 0.0)
    assert np.all(v <= no_coast + TOL_MPS)
    assert v[braking_starts] < no_coast[braking_starts]


def test_on_a_descent_the_regenerative_brake_holds_it_brakes_in_cycles():
    v = _curve(_grid(30_000.0, _regen_cannot_hold_w()))
    apply = _apply_mps()
    release = max(apply - kmh_to_mps(DEFAULT_HUMAN.cycle_release_below_kmh), kmh_to_mps(40.0))
    first = int(np.argmax(v >= apply - 1e-6))
    # the first 18 km of the descent, after it first reached its speed (the braking for
    # the stop, at the planning brake net of the descent, starts some 6 km out): between
    # the release and the apply speeds
    middle = v[first - 1 : int(0.6 * len(v))]
    assert middle.min() >= release - 0.2  # [m/s]: one grid step's deceleration below it
    assert middle.max() <= apply + TOL_MPS
    # applications (the first as it reaches its speed): the speed turns down at the apply
    # speed, more than once on 30 km
    turns = np.flatnonzero((np.diff(middle[:-1]) >= 0.0) & (np.diff(middle[1:]) < 0.0))
    assert len(turns) >= 2
    assert np.all(middle[turns + 1] >= apply - 0.05)


def test_on_a_descent_the_regenerative_brake_can_hold_it_holds_its_speed():
    v = _curve(_grid(30_000.0, -3.0))
    first = int(np.argmax(v >= _apply_mps() - 1e-6))
    middle = v[first : int(0.6 * len(v))]
    assert middle.min() == pytest.approx(_apply_mps())


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("margin_kmh", -1.0),
        ("reaction_s", float("nan")),
        ("coast_before_brake_m", 1e9),
        ("cycle_decel_mps2", 0.0),
        ("cycle_run_up_mps2", "fast"),
    ],
)
def test_a_bad_parameter_is_refused_by_name(field, value):
    with pytest.raises(ConfigError, match=field):
        HumanDriving(**{field: value})


# ----------------------------------------------------------------------- its reaction


def _twins(kind: str) -> tuple:
    """Two human drivers of the same train, 400 s into their first section."""
    day = line_scenario_from_mapping(BASE)
    service = day.services[0]
    drivers = [line_train(day, service, False, DEFAULT_HUMAN)[0] for _ in range(2)]
    t = service.stops[0].departure_s + 400.0
    for driver in drivers:
        driver.at(t)
    told, untold = drivers
    head, _ = told.at(t)
    sign = 1.0 if told.direction == TravelDirection.UP else -1.0
    if kind == "cab signal":
        # close enough that its stop for it starts at once
        red = head + sign * 2_000.0
        told.cab_signal(red, red + sign * 2_000.0, t)
    else:
        start, end = sorted((head + sign * 2_500.0, head + sign * 4_500.0))
        tsr = TsrSet(7, start, end, kmh_to_mps(30.0), 0.0, 4.0e9)
        applied = apply_tsr(tsr, told.preset.train.length_m, told.direction)
        told.on_event(TsrApplied(applied), day.epoch_s + t)
    return told, untold, t


@pytest.mark.parametrize("kind", ["cab signal", "TSR"])
def test_it_acts_on_what_it_is_told_its_reaction_time_later(kind):
    told, untold, t = _twins(kind)
    reaction = DEFAULT_HUMAN.reaction_s
    # until its reaction time is up it drives on as the twin that was told nothing
    for dt in np.arange(0.0, reaction - 0.05, 0.5):
        assert told.at(t + dt) == untold.at(t + dt)
    # then it brakes
    later = t + reaction + 60.0
    assert told.at(later)[1] < untold.at(later)[1] - 1.0


# ------------------------------------------------------------------------- line runs


@pytest.fixture(scope="module")
def human_day():
    """The short test day (a TSR, a failure, a radio dead zone), driven by the human."""
    return run_line(line_scenario_from_mapping(BASE), driver="human")


@pytest.mark.slow
def test_its_day_is_safe_and_every_train_arrives(human_day):
    kpis = human_day.kpis()
    assert kpis["driver"] == "human"
    for kpi in ("tsr_violations", "target_points_passed", "overspeeds", "tsr_applied_twice"):
        assert kpis[kpi] == 0, (kpi, kpis[kpi])
    assert all(train["finished"] for train in kpis["trains"].values())
    # it keeps its margin under the 80 km/h line speed, the ATO's tracking aside (the
    # other drivers come within 3.1-3.4 km/h of their 5 km/h margin: docs/line-run.md)
    top = max(float(rows[:, 2].max()) for rows in human_day.trace.values())
    assert top <= kmh_to_mps(80.0 - DEFAULT_HUMAN.margin_kmh + 2.0)
    # the baseline's rules: no re-timing and no planned-curve report
    assert kpis["retiming"]["runs"] == 0


@pytest.mark.slow
def test_the_same_seed_gives_the_same_numbers(human_day):
    again = run_line(line_scenario_from_mapping(BASE), driver="human")
    first, second = human_day.kpis(), again.kpis()
    for kpis in (first, second):
        kpis.pop("wall_s"), kpis.pop("realtime_factor")
    assert first == second
    for train, rows in human_day.trace.items():
        assert np.array_equal(rows, again.trace[train])


@pytest.mark.slow
def test_the_kpi_object_names_each_baseline(human_day):
    day = line_scenario_from_mapping(BASE)
    advised = run_line(day, until_s=1800.0)
    minimum = run_line(day, advised=False, until_s=1800.0)
    kpis = advised.kpis(minimum, human_day)
    assert list(kpis["baselines"]) == list(BASELINES)
    assert kpis["baselines"]["minimum-time"] == kpis["baseline"]
    assert kpis["baseline"] == {k: minimum.kpis()[k] for k in kpis["baseline"]}
    assert kpis["baselines"]["human"] == {k: human_day.kpis()[k] for k in kpis["baseline"]}
    assert kpis["baseline_energy_kwh"] == minimum.kpis()["energy_kwh"]
    assert kpis["human_baseline_energy_kwh"] == human_day.kpis()["energy_kwh"]
    # the human baseline alone: no minimum-time figures
    alone = advised.kpis(human=human_day)
    assert "baseline" not in alone and "baseline_energy_kwh" not in alone
    assert list(alone["baselines"]) == ["human"]


def test_the_drivers_are_named_once():
    assert set(BASELINES) < set(DRIVERS) and "advised" not in BASELINES
    assert BASELINE_NAMES == BASELINES  # the command line's list is the driver's


def test_an_unknown_driver_is_refused_by_name():
    day = line_scenario_from_mapping(BASE)
    with pytest.raises(ConfigError, match="driver"):
        run_line(day, driver="robot")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="advised"):
        run_line(day, advised=False, driver="advised")


@pytest.mark.parametrize("value", ["", "human,human", "minimum-time,robot", "fastest"])
def test_bad_baselines_are_refused(tmp_path, capsys, value):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    assert main(["line", "simulate", str(path), "--baselines", value]) == 2
    assert "--baselines" in capsys.readouterr().err
