"""The simulated radio channel (cosim/channel.py): loss, latency, dead zones, outages,
order, seeds, and bad input named by field."""

from __future__ import annotations

import itertools
import math
import statistics

import pytest
from scipy import stats

from railpilot.cosim.channel import ChannelModel, DeadZone, Outage, RadioChannel
from railpilot.errors import ConfigError
from railpilot.schema.channel import ChannelFileTable


def send_many(channel: RadioChannel, n: int, *, dt_s: float = 1.0, position_m: float = 0.0):  # type: ignore[no-untyped-def]
    return [channel.transmit("up", k * dt_s, position_m) for k in range(n)]


def test_the_loss_rate_is_the_models_within_sampling_error() -> None:
    n, loss = 20_000, 0.3
    arrivals = send_many(RadioChannel(ChannelModel(loss=loss), seed=1, train_id=7), n)
    lost = sum(a is None for a in arrivals)
    # a two-sided binomial test at the 0.1 % level: a biased draw fails it
    assert stats.binomtest(lost, n, loss).pvalue > 1e-3


def test_latency_is_the_minimum_plus_a_lognormal_excess_with_the_given_median() -> None:
    model = ChannelModel(latency_min_s=0.05, latency_median_s=0.2, latency_sigma=0.4)
    channel = RadioChannel(model, seed=2, train_id=1)
    sent = [k * 10.0 for k in range(5000)]  # far apart: the order rule never applies
    excess = [channel.transmit("down", t, None) - t - 0.05 for t in sent]  # type: ignore[operator]
    assert min(excess) > 0
    logs = [math.log(e) for e in excess]
    # log of the excess is normal with mu = log(median - min) and sigma = 0.4
    result = stats.kstest(logs, "norm", args=(math.log(0.15), 0.4))
    assert result.pvalue > 1e-3
    assert statistics.median(excess) == pytest.approx(0.15, rel=0.05)


def test_packets_of_one_direction_arrive_in_order() -> None:
    channel = RadioChannel(
        ChannelModel(latency_min_s=0.0, latency_median_s=0.5, latency_sigma=2.0), 3, 1
    )
    arrivals = [channel.transmit("up", k * 0.01, None) for k in range(2000)]
    assert all(b >= a for a, b in itertools.pairwise(arrivals))  # type: ignore[operator]


def test_nothing_crosses_a_dead_zone_or_an_outage_and_the_cause_is_counted() -> None:
    model = ChannelModel(dead_zones=(DeadZone(10.0, 12.0),), outages=(Outage(100.0, 200.0),))
    channel = RadioChannel(model, seed=4, train_id=1)
    assert channel.transmit("up", 5.0, 11_000.0) is None  # inside the zone
    assert channel.transmit("up", 5.0, 12_000.0) is None  # its end is inside
    assert channel.transmit("up", 5.0, 12_001.0) is not None
    assert channel.transmit("down", 150.0, 50_000.0) is None  # outage, anywhere
    assert channel.transmit("down", 200.0, 50_000.0) is not None  # the outage has ended
    assert channel.counters.lost == {"random": 0, "dead_zone": 2, "outage": 1}
    assert channel.counters.packets == 5 and channel.counters.delivered == 2
    assert not channel.up(150.0, None) and channel.up(99.0, None)


def test_the_same_seed_gives_the_same_draws_and_trains_draw_independently() -> None:
    model = ChannelModel(loss=0.2)
    a = send_many(RadioChannel(model, 9, 1), 500)
    b = send_many(RadioChannel(model, 9, 1), 500)
    other_train = send_many(RadioChannel(model, 9, 2), 500)
    other_seed = send_many(RadioChannel(model, 10, 1), 500)
    assert a == b
    assert a != other_train and a != other_seed


@pytest.mark.parametrize(
    ("table", "field"),
    [
        ({"loss": 1.5}, "channel.loss"),
        ({"loss": "x"}, "channel.loss"),
        ({"latency_min_s": 0.3, "latency_median_s": 0.2}, "channel.latency_median_s"),
        ({"latency_sigma": float("nan")}, "channel.latency_sigma"),
        ({"bandwidth": 3}, "channel.bandwidth"),
        ({"dead_zones": [{"start_km": 5, "end_km": 4}]}, "channel.dead_zones[0].end_km"),
        (
            {"dead_zones": [{"start_km": 1, "end_km": 2}, {"start_km": -1, "end_km": 2}]},
            "channel.dead_zones[1].start_km",
        ),
        ({"dead_zones": [{"start_km": 5}]}, "channel.dead_zones[0]"),
        ({"dead_zones": [{"start_km": 5, "end_km": 6, "x": 1}]}, "channel.dead_zones[0].x"),
        ({"dead_zones": "km 5"}, "channel.dead_zones"),
        ({"outages": [{"start_s": 10, "end_s": 10}]}, "channel.outages[0].end_s"),
    ],
)
def test_bad_channel_tables_are_refused_naming_the_field(table: dict, field: str) -> None:
    with pytest.raises(ConfigError) as info:
        ChannelModel.from_mapping(table)
    assert info.value.field == field


def test_a_table_builds_the_model() -> None:
    model = ChannelModel.from_mapping(
        {
            "loss": 0.3,
            "dead_zones": [{"start_km": 120, "end_km": 125}],
            "outages": [{"start_s": 600, "end_s": 660}],
        }
    )
    assert model == ChannelModel(
        loss=0.3, dead_zones=(DeadZone(120, 125),), outages=(Outage(600, 660),)
    )


def test_the_file_formats_defaults_are_the_models() -> None:
    """A [channel] table that leaves a number out gets the model's default, and the JSON
    Schema shows that same default."""
    defaults = ChannelModel()
    for key in ("latency_min_s", "latency_median_s", "latency_sigma", "loss"):
        assert ChannelFileTable.model_fields[key].default == getattr(defaults, key), key
    assert ChannelModel.from_mapping({}) == defaults


@pytest.mark.parametrize(
    ("table", "field", "value", "allowed"),
    [
        (
            {"dead_zones": [{"start_km": 5}]},
            "channel.dead_zones[0]",
            {"start_km": 5},
            "a table with end_km",
        ),
        ({"outages": [{}]}, "channel.outages[0]", {}, "a table with end_s, start_s"),
        ({"outages": [3]}, "channel.outages[0]", 3, "a table"),
        ({"outages": {"start_s": 1}}, "channel.outages", {"start_s": 1}, "a list of tables"),
        ({"loss": True}, "channel.loss", True, "a probability 0..0.99"),
        ({"latency_min_s": 11}, "channel.latency_min_s", 11, "0..10 s"),
        ({"latency_sigma": "x"}, "channel.latency_sigma", "x", "0..3"),
        (
            {"dead_zones": [{"start_km": -1, "end_km": 2}]},
            "channel.dead_zones[0].start_km",
            -1,
            "a km post >= 0",
        ),
        (
            {"zz": 1, "aa": 2},
            "channel.zz",
            1,
            "one of dead_zones, latency_median_s, latency_min_s, latency_sigma, loss, outages",
        ),
    ],
)
def test_a_bad_channel_table_names_the_value_and_what_is_allowed(
    table: dict, field: str, value: object, allowed: str
) -> None:
    with pytest.raises(ConfigError) as info:
        ChannelModel.from_mapping(table)
    assert (info.value.field, info.value.value, info.value.allowed) == (field, value, allowed)
