"""The scenario's radio on a live train's link (cosim/live_train.py ``ChannelRadio``): the
co-simulation's channel model, asked on the run's clock from where the train is, its
travel times given in the wall clock's seconds the proxy waits."""

from __future__ import annotations

from numpy.testing import assert_allclose

from railpilot.cosim.channel import ChannelModel, DeadZone, Outage, RadioChannel
from railpilot.cosim.live_train import ChannelRadio

EPOCH = 1_800_000_000.0
SPEEDUP = 60.0


class FakeClock:
    """The run's clock at a time the test sets [s since the epoch], ``SPEEDUP`` times the
    wall's."""

    def __init__(self, t_s: float) -> None:
        self.now_s = EPOCH + t_s

    def __call__(self) -> float:
        return self.now_s

    def wall_s(self, span_s: float) -> float:
        return span_s / SPEEDUP


def radio(model: ChannelModel, t_s: float, head_m: float) -> tuple[ChannelRadio, FakeClock]:
    clock = FakeClock(t_s)
    channel = RadioChannel(model, seed=1, train_id=101, origin_s=EPOCH)
    return ChannelRadio(channel, clock, lambda: head_m), clock  # type: ignore[arg-type]


def test_in_a_dead_zone_there_is_no_radio_and_every_packet_is_lost() -> None:
    model = ChannelModel(dead_zones=(DeadZone(5.0, 6.0),))
    inside, _ = radio(model, 100.0, 5_500.0)
    assert not inside.up()
    assert inside.packet_delay_s("up") is None
    assert inside.packet_delay_s("down") is None
    assert inside.channel.counters.lost["dead_zone"] == 2
    outside, _ = radio(model, 100.0, 6_500.0)
    assert outside.up()
    assert outside.packet_delay_s("up") is not None


def test_an_outage_is_timed_from_the_start_of_the_run() -> None:
    model = ChannelModel(outages=(Outage(600.0, 900.0),))
    during, clock = radio(model, 700.0, 1_000.0)
    assert not during.up()
    assert during.packet_delay_s("up") is None
    clock.now_s = EPOCH + 900.0
    assert during.up()


def test_a_packet_travels_the_channel_s_latency_in_wall_seconds_of_the_run_s_clock() -> None:
    # latency fixed at 0.12 s of the run: 2 ms of wall clock at 60x
    model = ChannelModel(latency_min_s=0.12, latency_median_s=0.12)
    live, _ = radio(model, 10.0, 1_000.0)
    # (to the resolution of epoch seconds in a float: 0.24 us)
    assert_allclose(live.packet_delay_s("up"), 0.12 / SPEEDUP, rtol=0, atol=1e-8)


def test_it_draws_what_the_co_simulation_s_channel_of_the_train_draws() -> None:
    # a channel of the same model, seed and train (as LinkSim makes it) asked directly:
    # the same losses and latencies, packet for packet (the radio draws once a packet)
    model = ChannelModel(loss=0.3)
    live, clock = radio(model, 10.0, 1_000.0)
    twin = RadioChannel(model, seed=1, train_id=101, origin_s=EPOCH)
    for k in range(200):
        direction = "up" if k % 3 else "down"
        delay = live.packet_delay_s(direction)
        arrival = twin.transmit(direction, clock.now_s, 1_000.0)
        assert (delay is None) == (arrival is None)
        if arrival is not None:
            assert_allclose(delay, (arrival - clock.now_s) / SPEEDUP, rtol=1e-9)
        clock.now_s += 0.5
    assert live.channel.counters.lost["random"] > 0
