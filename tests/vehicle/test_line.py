"""Line model (railpilot.vehicle.line): gradients, curves, speed limits by position."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from railpilot.errors import ConfigError
from railpilot.vehicle.line import Line, Segment


def test_level_line_has_no_additional_resistance():
    assert_array_equal(Line().additional_resistance([0.0, 1e4]), [0.0, 0.0])


def test_gradient_applies_inside_its_segment_only():
    # 3 per mille uphill on [100, 200) m -> 3 N/kN there, 0 outside; end is exclusive
    line = Line(gradients=(Segment(100.0, 200.0, 3.0),))
    assert_array_equal(
        line.additional_resistance([99.9, 100.0, 150.0, 199.9, 200.0]), [0.0, 3.0, 3.0, 3.0, 0.0]
    )


def test_downgrade_gives_negative_resistance():
    line = Line(gradients=(Segment(0.0, 50.0, -2.5),))
    assert line.additional_resistance(10.0) == -2.5


def test_overlapping_gradient_and_curve_add():
    # 2 per mille on [0, 300) plus R = 600 m curve (600/600 = 1 N/kN) on [100, 200)
    line = Line(gradients=(Segment(0.0, 300.0, 2.0),), curves=(Segment(100.0, 200.0, 600.0),))
    assert_allclose(line.additional_resistance([50.0, 150.0, 250.0]), [2.0, 3.0, 2.0])


def test_speed_limit_is_the_lowest_in_force():
    line = Line(speed_limits=(Segment(0.0, 500.0, 20.0), Segment(200.0, 300.0, 12.0)))
    assert_array_equal(line.speed_limit([100.0, 250.0, 400.0, 600.0]), [20.0, 12.0, 20.0, np.inf])


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"gradients": (Segment(200.0, 100.0, 1.0),)}, "line.gradients[0]"),
        ({"gradients": (Segment(0.0, 100.0, np.nan),)}, "line.gradients[0]"),
        ({"curves": (Segment(0.0, 100.0, -300.0),)}, "line.curves[0].radius_m"),
        ({"speed_limits": (Segment(0.0, 1.0, 0.0),)}, "line.speed_limits[0].limit"),
    ],
)
def test_bad_segment_raises_config_error_naming_it(kwargs, field):
    with pytest.raises(ConfigError) as info:
        Line(**kwargs)
    assert info.value.field == field
