"""The re-timing LP (railpilot.ground.running_time_lp).

Checked against independent computations: optima worked out by hand on one train and two
sections; every constraint re-checked numerically on random instances (leaders found with a
dictionary, energies with ``np.interp`` on the knots); the LP's objective never above the
fixed plan's; a brute-force grid search over the running times of a tiny instance (the
earliest schedule for given running times written out again here); the lower convex hull;
the fallback; and errors that name the field.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.ground.running_time_lp import (
    STATUS_FALLBACK,
    STATUS_FIXED,
    STATUS_OPTIMAL,
    TIE_BREAK,
    CommittedSection,
    EnergyCurve,
    RetimeProblem,
    RetimeResult,
    Section,
    TrainPlan,
    fixed_plan,
    proportional_slack,
    retime,
)

TOL_S = 1e-5

# ------------------------------------------------------------------------- helpers


def hand_sections() -> tuple[Section, Section]:
    """Two sections whose optimum is worked out by hand below.

    A: 100 s at the fastest, 120 s planned; energy 50 -> 30 -> 25 kWh at 100, 120, 140 s
       (slopes -1 and -0.25 kWh/s).
    B: 200 s at the fastest, 220 s planned; energy 80 -> 70 -> 66 kWh at 200, 220, 240 s
       (slopes -0.5 and -0.2 kWh/s).
    """
    a = Section(1, 2, 100.0, 120.0, EnergyCurve((100.0, 120.0, 140.0), (50.0, 30.0, 25.0)))
    b = Section(2, 3, 200.0, 220.0, EnergyCurve((200.0, 220.0, 240.0), (80.0, 70.0, 66.0)))
    return a, b


def one_train(delay_s: float, energy_weight: float) -> RetimeProblem:
    a, b = hand_sections()
    train = TrainPlan("T1", (a, b), (0.0, 130.0), (10.0,), earliest_departure_s=delay_s)
    return RetimeProblem((train,), headway_s=60.0, now_s=0.0, energy_weight_s_per_kwh=energy_weight)


def energy_interp(section: Section, r: float) -> float:
    """The curve at ``r``, independently: linear between knots, flat beyond the last."""
    return float(np.interp(r, section.energy.times_s, section.energy.energy_kwh))


def check_constraints(problem: RetimeProblem, result: RetimeResult, lp: bool = True) -> None:
    """Every constraint of the model, re-checked; ``lp``: also the latest arrivals."""
    h = problem.headway_s
    seen: dict[tuple[int, int], tuple[float, float]] = {}
    assert [t.train_id for t in result.trains] == [t.train_id for t in problem.trains]
    for plan, times in zip(problem.trains, result.trains, strict=True):
        d, r = times.departure_s, times.running_s
        a = d + r
        assert_allclose(times.arrival_s, a)
        assert d[0] >= max(plan.earliest_departure_s, problem.now_s) - TOL_S
        for j, s in enumerate(plan.sections):
            assert s.min_running_s - TOL_S <= r[j] <= s.upper_running_s + TOL_S
            assert d[j] >= plan.planned_departures_s[j] - TOL_S, "left early"
            if j > 0:
                assert d[j] >= a[j - 1] + plan.min_dwell_s[j - 1] - TOL_S, "dwell"
            key = (s.from_station, s.to_station)
            if key in seen:
                lead_d, lead_a = seen[key]
                assert d[j] >= lead_d + h - TOL_S, f"departure headway on {key}"
                assert a[j] >= lead_a + h - TOL_S, f"arrival headway on {key}"
            assert times.energy_kwh[j] == pytest.approx(energy_interp(s, r[j]), abs=1e-6)
        planned_arrival = plan.planned_departures_s[-1] + plan.sections[-1].planned_running_s
        assert times.lateness_s == pytest.approx(max(0.0, a[-1] - planned_arrival), abs=1e-9)
        if lp:
            assert a[-1] <= plan.latest_arrival_s + TOL_S
        for c in plan.committed:
            seen[(c.from_station, c.to_station)] = (c.departure_s, c.arrival_s)
        for j, s in enumerate(plan.sections):
            seen[(s.from_station, s.to_station)] = (d[j], a[j])


def random_curve(rng: np.random.Generator, t_min: float, pieces: int) -> EnergyCurve:
    times = t_min + np.concatenate([[0.0], np.cumsum(rng.integers(5, 40, pieces))])
    slopes = -np.sort(rng.uniform(0.05, 6.0, pieces))[::-1]  # steepest first: convex
    energy = rng.uniform(-500, 2000) + np.concatenate([[0.0], np.cumsum(slopes * np.diff(times))])
    return EnergyCurve(tuple(times), tuple(energy))


def random_problem(
    rng: np.random.Generator,
    n_trains: int,
    n_sections: int,
    *,
    with_latest: bool = False,
    integer: bool = False,
) -> RetimeProblem:
    """Trains on one route, front first, each a little further along than the one behind;
    the ones ahead with committed sections; random delays, weights and dwells."""
    route = []
    for j in range(n_sections):
        t_min = float(rng.integers(60, 400))
        curve = random_curve(rng, t_min, int(rng.integers(1, 6)))
        planned = t_min + float(rng.integers(0, 40))
        route.append(Section(j + 1, j + 2, t_min, planned, curve))
    dwell = rng.integers(0, 30, n_sections).astype(float)
    headway = float(rng.integers(30, 150))
    starts = np.sort(rng.integers(0, max(1, n_sections // 2), n_trains))[::-1]
    run = np.array([s.planned_running_s for s in route])
    spacing = float(rng.integers(int(headway) // 2, int(headway) + 120))
    trains = []
    for k in range(n_trains):
        extra = rng.integers(0, 20, n_sections).astype(float)  # planned dwell beyond minimum
        step = run + dwell + extra
        dep = k * spacing + np.concatenate([[0.0], np.cumsum(step[:-1])])
        first = int(starts[k])
        committed = tuple(
            CommittedSection(j + 1, j + 2, dep[j], dep[j] + run[j]) for j in range(first)
        )
        delay = float(rng.choice([0.0, 0.0, rng.integers(0, 400)]))
        latest = math.inf
        if with_latest and rng.random() < 0.5:
            latest = dep[-1] + run[-1] + float(rng.integers(0, 600))
        trains.append(
            TrainPlan(
                f"T{k}",
                tuple(route[first:]),
                tuple(dep[first:]),
                tuple(dwell[first:-1]),
                float(dep[first]) + delay,
                weight=float(rng.integers(1, 4)) if integer else float(rng.uniform(0.2, 3.0)),
                latest_arrival_s=latest,
                committed=committed,
            )
        )
    now = min(float(t.planned_departures_s[0]) for t in trains) - 10.0
    weight = float(rng.choice([0.05, 0.25, 0.5, 1.0]))
    return RetimeProblem(tuple(trains), headway, now, weight)


def tie_break(result: RetimeResult) -> float:
    return TIE_BREAK * float(sum(np.sum(t.departure_s + t.arrival_s) for t in result.trains))


# ------------------------------------------------------------------ optimum by hand


def test_one_train_recovers_on_the_cheapest_section_first() -> None:
    # 30 s late, energy worth 0.5 s/kWh. Gaining a second on B costs 0.5 kWh (0.25 s),
    # on A 1 kWh (0.5 s), both less than the second of lateness they save: B gives all
    # its 20 s of slack, A the remaining 10 s. Running slower than planned saves at most
    # 0.25 kWh/s (0.125 s) on A: not worth a second late. Objective 0.5 (40 + 80) = 60.
    result = retime(one_train(30.0, 0.5))
    assert result.status == STATUS_OPTIMAL
    times = result.trains[0]
    assert_allclose(times.running_s, [110.0, 200.0], atol=1e-6)
    assert_allclose(times.departure_s, [30.0, 150.0], atol=1e-6)
    assert times.lateness_s == pytest.approx(0.0, abs=1e-6)
    assert_allclose(times.energy_kwh, [40.0, 80.0], atol=1e-6)
    assert result.objective_s == pytest.approx(60.0, abs=1e-6)


def test_one_train_stays_late_when_energy_is_dear() -> None:
    # at 3 s/kWh a second gained costs 1.5 s on B and 3 s on A: keep the plan, 30 s late
    result = retime(one_train(30.0, 3.0))
    times = result.trains[0]
    assert_allclose(times.running_s, [120.0, 220.0], atol=1e-6)
    assert times.lateness_s == pytest.approx(30.0, abs=1e-6)
    assert result.objective_s == pytest.approx(30.0 + 3.0 * (30.0 + 70.0), abs=1e-6)


def test_a_train_on_time_runs_its_plan() -> None:
    result = retime(one_train(0.0, 0.5))
    assert_allclose(result.trains[0].running_s, [120.0, 220.0], atol=1e-6)
    assert_allclose(result.trains[0].departure_s, [0.0, 130.0], atol=1e-6)


def test_fixed_plan_by_hand() -> None:
    # the leader 100 s late; the follower planned 150 s behind with a 120 s headway: held
    # 70 s at the first departure; its arrival headway then holds by itself
    a, b = hand_sections()
    lead = TrainPlan("L", (a, b), (0.0, 130.0), (10.0,), earliest_departure_s=100.0)
    follow = TrainPlan("F", (a, b), (150.0, 280.0), (10.0,), earliest_departure_s=150.0)
    problem = RetimeProblem((lead, follow), 120.0, 0.0, 0.5)
    result = fixed_plan(problem)
    assert result.status == STATUS_FIXED
    assert_allclose(result.trains[0].departure_s, [100.0, 230.0])
    assert_allclose(result.trains[1].departure_s, [220.0, 350.0])
    assert_allclose(result.lateness_s, [100.0, 70.0])
    assert result.total_energy_kwh == pytest.approx(2 * (30.0 + 70.0))
    check_constraints(problem, result)


def test_committed_leader_holds_the_follower() -> None:
    # the leader left station 2 at 780 s and runs 2->3 slowly (expected at 3 at 1100 s);
    # the follower may leave 2 at 780 + 60 but arrive at 3 only at 1100 + 60: its
    # arrival, not its departure, binds (840 + 220 = 1060 s would be too early)
    a, b = hand_sections()
    lead = TrainPlan(
        "L",
        (Section(3, 4, 100.0, 120.0, a.energy),),
        (1110.0,),
        (),
        earliest_departure_s=1110.0,
        committed=(CommittedSection(2, 3, 780.0, 1100.0),),
    )
    follow = TrainPlan("F", (b,), (700.0,), (), earliest_departure_s=700.0)
    problem = RetimeProblem((lead, follow), 60.0, 700.0, 0.5)
    for result in (retime(problem), fixed_plan(problem)):
        check_constraints(problem, result)
        f = result.train("F")
        assert f.departure_s[0] >= 840.0 - TOL_S
        assert f.arrival_s[0] == pytest.approx(1160.0, abs=TOL_S)


def test_a_train_ahead_not_retimed_holds_the_follower() -> None:
    # the same leader's section 2->3, given as a train ahead that is not re-timed (on its
    # last section): the follower is held as by a committed leader, and alone in the
    # problem without it runs on its own
    _, b = hand_sections()
    follow = TrainPlan("F", (b,), (700.0,), (), earliest_departure_s=700.0)
    ahead = (CommittedSection(2, 3, 780.0, 1100.0),)
    held = RetimeProblem((follow,), 60.0, 700.0, 0.5, ahead)
    free = RetimeProblem((follow,), 60.0, 700.0, 0.5)
    for result in (retime(held), fixed_plan(held)):
        f = result.train("F")
        assert f.departure_s[0] >= 840.0 - TOL_S
        assert f.arrival_s[0] == pytest.approx(1160.0, abs=TOL_S)
    assert retime(free).train("F").arrival_s[0] < 1000.0
    with pytest.raises(ConfigError) as err:
        RetimeProblem((follow,), 60.0, 700.0, 0.5, ("not a section",))  # type: ignore[arg-type]
    assert err.value.field == "ahead"


def test_message_carries_the_running_times() -> None:
    times = retime(one_train(30.0, 0.5)).trains[0]
    message = times.message()
    assert [(t.from_station_id, t.to_station_id) for t in message.times] == [(1, 2), (2, 3)]
    assert_allclose([t.running_time_s for t in message.times], times.running_s)


# ----------------------------------------------------------- random instances, checks


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_lp_meets_every_constraint_and_beats_the_fixed_plan(seed: int) -> None:
    rng = np.random.default_rng(seed)
    problem = random_problem(rng, int(rng.integers(1, 7)), int(rng.integers(1, 7)))
    lp, fixed = retime(problem), fixed_plan(problem)
    assert lp.status == STATUS_OPTIMAL
    check_constraints(problem, lp)
    check_constraints(problem, fixed)
    # the fixed plan is a feasible point of the LP: the LP's objective is never above it
    # (up to the tie-break, which the LP minimises along with it)
    bound = fixed.objective_s + tie_break(fixed) - tie_break(lp)
    assert lp.objective_s <= bound + 1e-6 * max(1.0, abs(bound))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_latest_arrivals_are_met_or_the_fallback_says_so(seed: int) -> None:
    rng = np.random.default_rng(seed)
    problem = random_problem(
        rng, int(rng.integers(1, 6)), int(rng.integers(1, 6)), with_latest=True
    )
    result = retime(problem)
    if result.status == STATUS_OPTIMAL:
        check_constraints(problem, result)
    else:
        assert result.status == STATUS_FALLBACK
        assert "infeasible" in result.reason
        check_constraints(problem, result, lp=False)


def earliest_schedule_2x2(problem: RetimeProblem, r: np.ndarray) -> tuple[np.ndarray, ...]:
    """The earliest departures of two trains on two sections for running times ``r``
    (shape (4, ...): train 0's two, then train 1's), written out constraint by constraint."""
    lead, foll = problem.trains
    h = problem.headway_s
    p0, p1 = lead.planned_departures_s, foll.planned_departures_s
    d00 = np.maximum(max(p0[0], lead.earliest_departure_s, problem.now_s), 0 * r[0])
    d01 = np.maximum(p0[1], d00 + r[0] + lead.min_dwell_s[0])
    start = max(p1[0], foll.earliest_departure_s, problem.now_s)
    d10 = np.maximum.reduce([start + 0 * r[2], d00 + h, d00 + r[0] + h - r[2]])
    d11 = np.maximum.reduce(
        [p1[1] + 0 * r[3], d10 + r[2] + foll.min_dwell_s[0], d01 + h, d01 + r[1] + h - r[3]]
    )
    return d00, d01, d10, d11


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_brute_force_grid_agrees_with_the_lp(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # running times up to 24 s above the minimum: a grid of 25^4 points
    a = Section(1, 2, 100.0, 112.0, random_curve(rng, 100.0, 3), max_running_s=124.0)
    b = Section(2, 3, 150.0, 162.0, random_curve(rng, 150.0, 3), max_running_s=174.0)
    lead = TrainPlan(
        "L", (a, b), (0.0, 122.0), (10.0,), earliest_departure_s=float(rng.integers(0, 40))
    )
    foll = TrainPlan(
        "F",
        (a, b),
        (90.0, 212.0),
        (10.0,),
        earliest_departure_s=90.0,
        weight=float(rng.integers(1, 3)),
    )
    weight = float(rng.choice([0.1, 0.3, 0.6]))
    problem = RetimeProblem((lead, foll), 80.0, 0.0, weight)
    lp = retime(problem)
    check_constraints(problem, lp)
    # every combination of integer running times within the bounds
    axes = [np.arange(s.min_running_s, s.upper_running_s + 0.5) for s in (a, b, a, b)]
    r = np.stack(np.meshgrid(*axes, indexing="ij")).reshape(4, -1)
    _, d01, _, d11 = earliest_schedule_2x2(problem, r)
    late0 = np.maximum(0.0, d01 + r[1] - lead.planned_arrival_s)
    late1 = np.maximum(0.0, d11 + r[3] - foll.planned_arrival_s)
    energy = sum(
        np.interp(r[i], s.energy.times_s, s.energy.energy_kwh) for i, s in enumerate((a, b, a, b))
    )
    objective = lead.weight * late0 + foll.weight * late1 + weight * energy
    best = float(np.min(objective))
    # the LP's vertices lie on integer times here (integer knots, headway, dwells and
    # plan): the grid contains the optimum
    assert lp.objective_s == pytest.approx(best, abs=1e-4)


# -------------------------------------------------------------------- energy curves


def test_hull_is_convex_below_every_sample_and_cut_at_its_minimum() -> None:
    # a sawtooth like the planner's on a steep descent (docs/onboard.md), then a rise
    times = [1000.0, 1030.0, 1060.0, 1100.0, 1150.0, 1200.0, 1300.0, 1350.0]
    energy = [-19.0, 7.0, 39.0, 61.0, 78.0, -378.0, -300.0, -200.0]
    curve = EnergyCurve.from_samples(times, energy)
    assert curve.times_s == (1000.0, 1200.0)
    assert curve.energy_kwh == (-19.0, -378.0)
    assert np.all(curve.energy_at(np.array(times)) <= np.array(energy) + 1e-9)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_hull_of_random_samples(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 12))
    times = rng.uniform(100.0, 3000.0, n)
    energy = rng.uniform(-1000.0, 3000.0, n)
    curve = EnergyCurve.from_samples(times, energy)  # validates convex and non-increasing
    knots = set(zip(curve.times_s, curve.energy_kwh, strict=True))
    assert knots <= set(zip(times.tolist(), energy.tolist(), strict=True))
    assert np.all(curve.energy_at(times) <= energy + 1e-6)
    # the hull is the greatest such curve: a convex function below the samples cannot
    # be above the chord between two samples at a time between them
    for i in range(n):
        for j in range(n):
            if times[i] < times[j]:
                mid = 0.5 * (times[i] + times[j])
                assert curve.energy_at(mid) <= 0.5 * (energy[i] + energy[j]) + 1e-6
    assert curve.times_s[0] == pytest.approx(float(np.min(times)))
    assert curve.energy_kwh[-1] == pytest.approx(float(np.min(energy)))


def test_curve_is_flat_beyond_its_last_knot() -> None:
    curve = EnergyCurve((10.0, 20.0), (5.0, 1.0))
    assert_allclose(curve.energy_at(np.array([10.0, 15.0, 20.0, 40.0])), [5.0, 3.0, 1.0, 1.0])


# ------------------------------------------------------------------------ fallback


def test_infeasible_latest_arrival_falls_back_and_says_so(caplog: pytest.LogCaptureFixture) -> None:
    a, b = hand_sections()
    # 30 s late: 30 + 100 + 10 (dwell) + 200 = 340 s at best, asked for 250 s
    train = TrainPlan(
        "T1", (a, b), (0.0, 130.0), (10.0,), earliest_departure_s=30.0, latest_arrival_s=250.0
    )
    problem = RetimeProblem((train,), 60.0, 0.0, 0.5)
    with caplog.at_level(logging.WARNING, logger="railpilot.ground.running_time_lp"):
        result = retime(problem)
    assert result.status == STATUS_FALLBACK and result.fallback
    assert "infeasible" in result.reason and "T1" in result.reason
    assert "latest arrival still missed by T1" in result.reason
    assert any("proportional slack" in r.getMessage() for r in caplog.records)
    # 30 s late with 40 s of slack (20 + 20), and 30 s more to meet 250 s: all of it used
    assert_allclose(result.trains[0].running_s, [100.0, 200.0])
    check_constraints(problem, result, lp=False)


def test_headway_infeasible_names_the_headway() -> None:
    # each alone could make it; the follower's latest arrival is before the leader's
    # earliest possible arrival plus the headway
    a, b = hand_sections()
    lead = TrainPlan("L", (a, b), (0.0, 130.0), (10.0,), earliest_departure_s=0.0)
    # alone F arrives at 430 s at best; behind L (330 s at best) with a 150 s headway, 480 s
    foll = TrainPlan(
        "F", (a, b), (100.0, 230.0), (10.0,), earliest_departure_s=100.0, latest_arrival_s=450.0
    )
    result = retime(RetimeProblem((lead, foll), 150.0, 0.0, 0.5))
    assert result.status == STATUS_FALLBACK
    assert "headway" in result.reason


def test_proportional_slack_shares_the_slack_alike() -> None:
    a, b = hand_sections()
    # 30 s late (earliest 30 s), slack 20 s + 20 s: 3/4 of each section's slack used
    train = TrainPlan("T1", (a, b), (0.0, 130.0), (10.0,), earliest_departure_s=30.0)
    problem = RetimeProblem((train,), 60.0, 0.0, 0.5)
    result = proportional_slack(problem)
    times = result.trains[0]
    assert_allclose(times.running_s, [105.0, 205.0])
    assert times.lateness_s == pytest.approx(0.0, abs=1e-9)
    check_constraints(problem, result)


# ---------------------------------------------------------------------- bad input


def curve() -> EnergyCurve:
    return EnergyCurve((100.0, 120.0), (50.0, 30.0))


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: EnergyCurve((120.0, 100.0), (30.0, 50.0)), "times_s"),  # unsorted knots
        (lambda: EnergyCurve((100.0, 100.0), (30.0, 20.0)), "times_s"),  # repeated knot
        (lambda: EnergyCurve((-1.0, 100.0), (30.0, 20.0)), "times_s"),  # negative time
        (lambda: EnergyCurve((100.0, 120.0, 140.0), (50.0, 49.0, 20.0)), "energy_kwh"),  # concave
        (lambda: EnergyCurve((100.0, 120.0), (30.0, 50.0)), "energy_kwh"),  # increasing
        (lambda: EnergyCurve((100.0, 120.0), (30.0,)), "energy_kwh"),  # lengths differ
        (lambda: EnergyCurve((), ()), "times_s"),
        (lambda: EnergyCurve((100.0, math.nan), (1.0, 0.0)), "times_s"),
        (lambda: EnergyCurve.from_samples([1.0, 2.0], [1.0]), "energy_kwh"),
        (lambda: Section(1, 2, -5.0, 120.0, curve()), "min_running_s"),
        (lambda: Section(1, 2, 90.0, 120.0, curve()), "min_running_s"),  # below the curve
        (lambda: Section(1, 2, 110.0, 105.0, curve()), "planned_running_s"),
        (lambda: Section(1, 2, 110.0, 115.0, curve(), max_running_s=112.0), "max_running_s"),
        (lambda: Section(1, 1, 110.0, 115.0, curve()), "to_station"),
        (lambda: Section(-1, 2, 110.0, 115.0, curve()), "from_station"),
        (lambda: CommittedSection(1, 2, 100.0, 50.0), "arrival_s"),
    ],
)
def test_bad_input_names_the_field(make, field: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ConfigError) as err:
        make()
    assert field in err.value.field


def plan(**changes: object) -> TrainPlan:
    a, b = hand_sections()
    args: dict[str, object] = dict(
        train_id="T1",
        sections=(a, b),
        planned_departures_s=(0.0, 130.0),
        min_dwell_s=(10.0,),
        earliest_departure_s=0.0,
    )
    args.update(changes)
    return TrainPlan(**args)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"planned_departures_s": (0.0,)}, "planned_departures_s"),
        ({"planned_departures_s": (0.0, 125.0)}, "planned_departures_s[1]"),  # within dwell
        ({"min_dwell_s": ()}, "min_dwell_s"),
        ({"min_dwell_s": (-1.0,)}, "min_dwell_s"),
        ({"sections": tuple(reversed(hand_sections()))}, "sections[1].from_station"),
        ({"sections": ()}, "sections"),
        ({"train_id": ""}, "train_id"),
        ({"weight": -1.0}, "weight"),
        ({"earliest_departure_s": math.inf}, "earliest_departure_s"),
        ({"latest_arrival_s": math.nan}, "latest_arrival_s"),
    ],
)
def test_bad_train_plan_names_the_field(changes: dict[str, object], field: str) -> None:
    with pytest.raises(ConfigError) as err:
        plan(**changes)
    assert field in err.value.field


def test_bad_problem_names_the_field() -> None:
    with pytest.raises(ConfigError) as err:
        RetimeProblem((plan(), plan()), 60.0, 0.0, 0.5)
    assert err.value.field == "trains"
    for kwargs, field in (
        ({"headway_s": -1.0}, "headway_s"),
        ({"now_s": math.nan}, "now_s"),
        ({"energy_weight_s_per_kwh": -0.1}, "energy_weight_s_per_kwh"),
    ):
        args = {"headway_s": 60.0, "now_s": 0.0, "energy_weight_s_per_kwh": 0.5} | kwargs
        with pytest.raises(ConfigError) as err:
            RetimeProblem((plan(),), **args)  # type: ignore[arg-type]
        assert err.value.field == field


def test_a_train_that_passed_the_one_ahead_is_refused() -> None:
    # the second train has run 1->2, which the first still has to run: not a fixed order
    b = hand_sections()[1]
    ahead = plan(train_id="A")
    behind = TrainPlan(
        "B",
        (b,),
        (300.0,),
        (),
        earliest_departure_s=300.0,
        committed=(CommittedSection(1, 2, 0.0, 120.0),),
    )
    with pytest.raises(ConfigError) as err:
        RetimeProblem((ahead, behind), 60.0, 0.0, 0.5)
    assert "committed" in err.value.field and "B" in err.value.field
