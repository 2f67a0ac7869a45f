"""The ``[montecarlo]`` spec (railpilot.scenario.montecarlo) and the loader's issue-4 tables.

Distributions are checked against their definitions (uniform on [min, max]; normal
truncated to [min, max] by resampling, whose mean is the truncated-normal mean
``mu + s (pdf(a) - pdf(b)) / (cdf(b) - cdf(a))``); the loader's ``[brake] model =
"lag-delay"``, ``[realism]`` and ``[montecarlo]`` tables against what they must build,
and their bad entries against the key and value the error must name.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.errors import ConfigError, ScenarioError
from railpilot.scenario.loader import load_scenario_and_spec, scenario_and_spec_from_mapping
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim.realism import Realism

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
N = 20_000


def phi(z):
    return math.exp(-z * z / 2) / math.sqrt(2 * math.pi)


def cdf(z):
    return 0.5 * (1 + math.erf(z / math.sqrt(2)))


# --- Distribution ---------------------------------------------------------------------


def test_uniform_samples_stay_within_bounds_and_fill_them():
    dist = Distribution("train.mass_t", "uniform", 482.4, 589.6)
    x = dist.sample(np.random.default_rng(1), N)
    assert x.min() >= 482.4 and x.max() <= 589.6
    # mean (a + b) / 2, std (b - a) / sqrt(12); 5 standard errors
    assert x.mean() == pytest.approx(536.0, abs=5 * 107.2 / math.sqrt(12 * N))
    assert x.min() < 482.4 + 1.0 and x.max() > 589.6 - 1.0


def test_truncated_normal_stays_within_bounds_with_the_truncated_mean():
    # N(0.3, 0.1) cut to [0.2, 0.5]: a = -1, b = 2 -> mean 0.32296; clipping instead of
    # resampling would give 0.3076, far outside the tolerance
    mu, s, low, high = 0.3, 0.1, 0.2, 0.5
    dist = Distribution("brake.delay_s", "normal", low, high, mean=mu, std=s)
    x = dist.sample(np.random.default_rng(2), N)
    assert x.min() >= low and x.max() <= high
    a, b = (low - mu) / s, (high - mu) / s
    expected = mu + s * (phi(a) - phi(b)) / (cdf(b) - cdf(a))
    assert x.mean() == pytest.approx(expected, abs=0.003)


def test_truncated_normal_piles_no_mass_on_the_bounds():
    dist = Distribution("brake.delay_s", "normal", 0.2, 0.5, mean=0.3, std=0.1)
    x = dist.sample(np.random.default_rng(3), N)
    assert np.count_nonzero((x == 0.2) | (x == 0.5)) == 0


def test_equal_bounds_give_that_value():
    for kind in ("uniform", "normal"):
        dist = Distribution("train.davis_scale", kind, 1.1, 1.1, mean=1.0, std=0.1)
        assert np.all(dist.sample(np.random.default_rng(0), 10) == 1.1)


BAD_DISTRIBUTIONS = [
    # (case, constructor arguments, the field the error names)
    ("min > max", ("train.mass_t", "uniform", 600.0, 500.0), "montecarlo.vary.train.mass_t.min"),
    ("unknown key", ("train.masss", "uniform", 1.0, 2.0), "montecarlo.vary.train.masss"),
    (
        "negative delay lower bound",
        ("brake.delay_s", "uniform", -0.1, 0.3),
        "montecarlo.vary.brake.delay_s.min",
    ),
    ("unknown kind", ("train.mass_t", "gamma", 1.0, 2.0), "montecarlo.vary.train.mass_t.dist"),
    (
        "infinite bound",
        ("train.mass_t", "uniform", 1.0, math.inf),
        "montecarlo.vary.train.mass_t.min",
    ),
    (
        "davis scale above 10",
        ("train.davis_scale", "uniform", 0.8, 10.5),
        "montecarlo.vary.train.davis_scale.max",
    ),
    ("brake gain above 10", ("brake.gain", "uniform", 0.9, 11.0), "montecarlo.vary.brake.gain.max"),
    (
        "adhesion above 1",
        ("realism.adhesion", "uniform", 0.1, 1.5),
        "montecarlo.vary.realism.adhesion.max",
    ),
]


@pytest.mark.parametrize(
    ("args", "field"), [pytest.param(*c[1:], id=c[0]) for c in BAD_DISTRIBUTIONS]
)
def test_bad_distribution_raises_config_error_naming_the_key(args, field):
    with pytest.raises(ConfigError) as info:
        Distribution(*args)
    assert info.value.field == field


@pytest.mark.parametrize("std", [0.0, -0.1, math.nan])
def test_normal_needs_a_positive_std(std):
    with pytest.raises(ConfigError) as info:
        Distribution("train.mass_t", "normal", 400.0, 600.0, mean=500.0, std=std)
    assert info.value.field == "montecarlo.vary.train.mass_t.std"


# --- MonteCarloSpec -------------------------------------------------------------------

VARY = (
    Distribution("train.mass_t", "uniform", 270.0, 330.0),
    Distribution("brake.delay_s", "uniform", 1.05, 1.35),
    Distribution("train.davis_scale", "normal", 0.8, 1.2, mean=1.0, std=0.1),
)


def test_samples_depend_only_on_the_seed():
    first = MonteCarloSpec(runs=50, seed=4, vary=VARY).samples()
    again = MonteCarloSpec(runs=50, seed=4, vary=VARY, chunk=7).samples()
    other = MonteCarloSpec(runs=50, seed=5, vary=VARY).samples()
    assert np.array_equal(first[1], again[1])
    for key in first[0]:
        assert np.array_equal(first[0][key], again[0][key])
        assert not np.array_equal(first[0][key], other[0][key])
    assert not np.array_equal(first[1], other[1])


def test_each_run_gets_a_distinct_seed():
    _, seeds = MonteCarloSpec(runs=1000, seed=0).samples()
    assert len(np.unique(seeds)) == 1000
    assert seeds.min() >= 0


def test_run_seeds_do_not_depend_on_what_varies():
    # adding a varied parameter leaves every run's disturbance seed alone
    _, plain = MonteCarloSpec(runs=30, seed=8).samples()
    _, varied = MonteCarloSpec(runs=30, seed=8, vary=VARY).samples()
    assert np.array_equal(plain, varied)


def test_run_seeds_do_not_depend_on_the_run_count():
    _, short = MonteCarloSpec(runs=40, seed=8).samples()
    _, long = MonteCarloSpec(runs=400, seed=8).samples()
    assert np.array_equal(short, long[:40])


def test_run_values_do_not_depend_on_the_run_count():
    short, _ = MonteCarloSpec(runs=40, seed=8, vary=VARY).samples()
    long, _ = MonteCarloSpec(runs=400, seed=8, vary=VARY).samples()
    for key in short:
        assert np.array_equal(short[key], long[key][:40]), key


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"runs": 0}, "montecarlo.runs"),
        ({"runs": 2.5}, "montecarlo.runs"),
        ({"seed": -1}, "montecarlo.seed"),
        ({"chunk": 0}, "montecarlo.chunk"),
    ],
)
def test_bad_spec_raises_config_error_naming_the_key(kwargs, field):
    with pytest.raises(ConfigError) as info:
        MonteCarloSpec(**kwargs)
    assert info.value.field == field


# --- the loader: [brake] model = "lag-delay", [realism], [montecarlo] ------------------

LAG_DELAY = {"model": "lag-delay", "lag_s": 0.4, "delay_s": 1.15, "max_decel_mps2": 1.2}


def test_lag_delay_brake_model_builds_a_lag_delay_brake():
    scenario, _ = scenario_and_spec_from_mapping({"name": "t", "brake": LAG_DELAY})
    assert scenario.brake == LagDelayBrake(lag_s=0.4, delay_s=1.15, max_decel_mps2=1.2)


def test_realism_table_parses_with_balises_in_km():
    realism = {
        "speed_noise_std_mps": 0.03,
        "speed_resolution_mps": 0.01,
        "wheel_scale_error": 0.005,
        "slide_slip": 0.1,
        "balises_km": [0.25, 0.2965, 1],
        "adhesion": 0.12,
        "slide_ratio": 0.7,
        "notches": 7,
        "seed": 3,
    }
    scenario, _ = scenario_and_spec_from_mapping({"name": "t", "realism": realism})
    assert scenario.realism.balises_m == pytest.approx((250.0, 296.5, 1000.0))
    assert scenario.realism == Realism(
        speed_noise_std_mps=0.03,
        speed_resolution_mps=0.01,
        wheel_scale_error=0.005,
        slide_slip=0.1,
        balises_m=scenario.realism.balises_m,
        adhesion=0.12,
        slide_ratio=0.7,
        notches=7,
        seed=3,
    )


def test_no_realism_table_is_the_idealised_world():
    scenario, spec = scenario_and_spec_from_mapping({"name": "t"})
    assert scenario.realism == Realism()
    assert spec is None


def test_montecarlo_table_parses():
    mapping = {
        "montecarlo": {
            "runs": 250,
            "seed": 17,
            "chunk": 50,
            "vary": {
                "train.mass_t": {"dist": "uniform", "min": 482.4, "max": 589.6},
                "train.davis_scale": {
                    "dist": "normal",
                    "mean": 1.0,
                    "std": 0.1,
                    "min": 0.8,
                    "max": 1.2,
                },
                "brake.delay_s": {"min": 0.2, "max": 0.5},  # uniform by default
            },
        }
    }
    _, spec = scenario_and_spec_from_mapping({"name": "t", **mapping})
    assert spec == MonteCarloSpec(
        runs=250,
        seed=17,
        chunk=50,
        vary=(
            Distribution("train.mass_t", "uniform", 482.4, 589.6),
            Distribution("train.davis_scale", "normal", 0.8, 1.2, mean=1.0, std=0.1),
            Distribution("brake.delay_s", "uniform", 0.2, 0.5),
        ),
    )


def test_region_accel_is_times_the_effective_mass():
    mapping = {
        "train": {"mass_t": 300.0, "rotating_mass_factor": 0.1},
        "disturbance": {"regions": [{"start_km": 0.1, "end_km": 0.2, "accel_mps2": 0.05}]},
    }
    scenario, _ = scenario_and_spec_from_mapping({"name": "t", **mapping})
    (region,) = scenario.disturbance.regions
    assert (region.start_m, region.end_m) == pytest.approx((100.0, 200.0))
    assert region.force_n == pytest.approx(0.05 * 300e3 * 1.1)


@pytest.mark.parametrize(
    ("name", "brake_type", "runs", "n_vary"),
    [
        ("paper000_montecarlo.toml", "EPBrake", 1000, 3),
        ("paper002_qsmc_stop.toml", "LagDelayBrake", 1000, 1),
        ("paper002_realistic.toml", "LagDelayBrake", 1000, 6),
    ],
)
def test_example_files_load_with_their_spec(name, brake_type, runs, n_vary):
    scenario, spec = load_scenario_and_spec(EXAMPLES / name)
    assert type(scenario.brake).__name__ == brake_type
    assert spec is not None
    assert (spec.runs, len(spec.vary)) == (runs, n_vary)


MC = "montecarlo"
BAD = [
    # (case, mapping, the key the error names, the value it names)
    (
        "distribution min > max",
        {MC: {"vary": {"train.mass_t": {"min": 600, "max": 500}}}},
        "montecarlo.vary.train.mass_t.min",
        (600.0, 500.0),
    ),
    (
        "negative delay in a distribution",
        {MC: {"vary": {"brake.delay_s": {"min": -0.1, "max": 0.3}}}},
        "montecarlo.vary.brake.delay_s.min",
        -0.1,
    ),
    (
        "typo in a varied key",
        {MC: {"vary": {"train.mas_t": {"min": 1, "max": 2}}}},
        "montecarlo.vary.train.mas_t",
        "train.mas_t",
    ),
    (
        "typo in a distribution",
        {MC: {"vary": {"train.mass_t": {"min": 1, "max": 2, "mean": 1.5}}}},
        "montecarlo.vary.train.mass_t.mean",
        1.5,
    ),
    ("typo in [montecarlo]", {MC: {"rnus": 5}}, "montecarlo.rnus", 5),
    ("zero runs", {MC: {"runs": 0}}, "montecarlo.runs", 0),
    (
        "normal with std 0",
        {
            MC: {
                "vary": {
                    "train.mass_t": {"dist": "normal", "mean": 5, "std": 0, "min": 1, "max": 9}
                }
            }
        },
        "montecarlo.vary.train.mass_t.std",
        0.0,
    ),
    (
        "key that does not apply to the brake",
        {MC: {"vary": {"brake.lag_s": {"min": 0.4, "max": 0.6}}}},
        "montecarlo.vary.brake.lag_s",
        0.4,
    ),
    ("negative brake delay", {"brake": {**LAG_DELAY, "delay_s": -0.5}}, "brake.delay_s", -0.5),
    (
        "delay shorter than the step",
        {"brake": {**LAG_DELAY, "delay_s": 0.005}},
        "brake.delay_s",
        0.005,
    ),
    (
        "EP key on a lag-delay brake",
        {"brake": {**LAG_DELAY, "air_lag_s": 0.5}},
        "brake.air_lag_s",
        0.5,
    ),
    ("unknown brake model", {"brake": {"model": "lagdelay"}}, "brake.model", "lagdelay"),
    ("notches = -1", {"realism": {"notches": -1}}, "realism.notches", -1),
    ("typo in [realism]", {"realism": {"speed_noise": 0.1}}, "realism.speed_noise", 0.1),
    ("balises not a list", {"realism": {"balises_km": 0.3}}, "realism.balises_km", 0.3),
    (
        "wheel scale error out of range",
        {"realism": {"wheel_scale_error": 0.5}},
        "realism.wheel_scale_error",
        0.5,
    ),
]


@pytest.mark.parametrize(("mapping", "key", "value"), [pytest.param(*c[1:], id=c[0]) for c in BAD])
def test_bad_entry_raises_scenario_error_naming_key_and_value(mapping, key, value):
    with pytest.raises(ScenarioError) as info:
        scenario_and_spec_from_mapping({"name": "t", **mapping})
    assert info.value.field == key
    assert info.value.value == value
    assert str(info.value).startswith(f"{key} = {value!r} is not allowed")


@pytest.mark.parametrize(
    "region",
    [
        pytest.param({"start_km": 0.1, "end_km": 0.2}, id="neither"),
        pytest.param(
            {"start_km": 0.1, "end_km": 0.2, "force_kn": 3.0, "accel_mps2": 0.05}, id="both"
        ),
    ],
)
def test_region_needs_exactly_one_of_force_and_accel(region):
    with pytest.raises(ScenarioError, match="exactly one of force_kn or accel_mps2") as info:
        scenario_and_spec_from_mapping({"name": "t", "disturbance": {"regions": [region]}})
    assert info.value.field.startswith("disturbance.regions[0].")


def test_bad_montecarlo_file_is_refused_when_read(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(
        'name = "t"\n[montecarlo.vary]\n"train.mass_t" = { min = 600.0, max = 500.0 }\n'
    )
    with pytest.raises(ScenarioError, match=r"montecarlo\.vary\.train\.mass_t\.min"):
        load_scenario_and_spec(path)


def test_spec_replace_is_checked_too():
    # the CLI's --runs goes through dataclasses.replace: the same checks apply
    with pytest.raises(ConfigError, match=r"montecarlo\.runs"):
        dataclasses.replace(MonteCarloSpec(), runs=-5)
