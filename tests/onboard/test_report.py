"""The planned-curve report (railpilot.onboard.report)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.link.codec import decode_body, encode_body
from railpilot.link.messages import PlannedCurve
from railpilot.onboard.planner import SpeedPlan
from railpilot.onboard.report import PlannedCurveReporter, remaining_time_s


def constant_speed_plan(length_m=1000.0, speed=10.0):
    s = np.linspace(0.0, length_m, 101)
    v = np.full(s.shape, speed)
    return SpeedPlan(s, v, length_m / speed, 0.0, 0.0, None, None, None, True)


def test_remaining_time_of_a_constant_speed_plan():
    plan = constant_speed_plan()
    assert_allclose(remaining_time_s(plan, 0.0), 100.0)
    assert_allclose(remaining_time_s(plan, 250.0), 75.0)
    assert remaining_time_s(plan, 2000.0) == 0.0


def test_remaining_time_is_numpys_interpolation_to_the_bit():
    # compiled for speed; the ground re-times on it, so it must not differ in any bit
    rng = np.random.default_rng(7)
    s = np.cumsum(rng.uniform(1.0, 30.0, 800))
    v = rng.uniform(0.0, 25.0, s.size)
    v[100:140] = 0.0  # a stretch at rest takes no time
    plan = SpeedPlan(s, v, 1.0, 0.0, 0.0, None, None, None, True)
    elapsed = plan.elapsed_s
    points = np.concatenate([rng.uniform(s[0] - 50.0, s[-1] + 50.0, 2000), s])
    for x in points:
        expected = max(0.0, float(elapsed[-1]) - float(np.interp(x, s, elapsed)))
        assert remaining_time_s(plan, float(x)) == expected


def test_first_update_reports_and_steady_running_does_not():
    reporter = PlannedCurveReporter()
    first = reporter.update(3, 4, 0.0, 600.0, now_s=0.0)
    assert first == PlannedCurve(3, 4, 0.0, 600.0)
    # on plan: elapsed grows as remaining shrinks, the prediction stays 600 s
    for t in range(1, 59):
        assert reporter.update(3, 4, float(t), 600.0 - t, now_s=float(t)) is None


def test_a_moved_prediction_is_reported():
    reporter = PlannedCurveReporter(threshold_s=1.0)
    reporter.update(3, 4, 0.0, 600.0, now_s=0.0)
    assert reporter.update(3, 4, 10.0, 590.5, now_s=10.0) is None  # 0.5 s late: not yet
    late = reporter.update(3, 4, 20.0, 581.2, now_s=20.0)  # 1.2 s late
    assert late == PlannedCurve(3, 4, 20.0, 581.2)


def test_a_new_station_pair_is_reported_at_once():
    reporter = PlannedCurveReporter()
    reporter.update(3, 4, 0.0, 600.0, now_s=0.0)
    assert reporter.update(4, 5, 0.0, 700.0, now_s=1.0) == PlannedCurve(4, 5, 0.0, 700.0)


def test_refresh_repeats_an_unchanged_report():
    reporter = PlannedCurveReporter(refresh_s=60.0)
    reporter.update(3, 4, 0.0, 600.0, now_s=0.0)
    assert reporter.update(3, 4, 59.0, 541.0, now_s=59.0) is None
    assert reporter.update(3, 4, 60.0, 540.0, now_s=60.0) == PlannedCurve(3, 4, 60.0, 540.0)


def test_the_report_travels_through_the_link_codec():
    message = PlannedCurveReporter().update(3, 4, 12.0, 345.0, now_s=0.0)
    # whole milliseconds on the wire
    assert decode_body(message.TYPE, encode_body(message)) == message


@pytest.mark.parametrize("kwargs", [{"threshold_s": 0.0}, {"refresh_s": float("nan")}])
def test_bad_parameters_name_the_field(kwargs):
    with pytest.raises(ConfigError) as err:
        PlannedCurveReporter(**kwargs)
    assert err.value.field.startswith("report.")
