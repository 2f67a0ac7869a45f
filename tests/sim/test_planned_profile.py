"""PlannedProfile (sim/drive_profile.py): a table of planned speeds as a reference."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.sim.drive_profile import PlannedProfile


def test_uniform_acceleration_then_braking_is_exact_in_time() -> None:
    # 0 -> 20 m/s at 0.5 m/s^2 over 400 m, then to rest at 1 m/s^2 over 200 m: v^2 linear
    x = np.array([0.0, 100.0, 400.0, 500.0, 600.0])
    v = np.sqrt(np.array([0.0, 100.0, 400.0, 200.0, 0.0]))
    ref = PlannedProfile(x, v)
    assert ref.duration_s == pytest.approx(40.0 + 20.0, rel=1e-12)
    t = np.array([10.0, 40.0, 50.0, 60.0])
    xs, vs, a = ref.sample(t)
    assert_allclose(xs, [25.0, 400.0, 400.0 + 20 * 10 - 0.5 * 100, 600.0], rtol=1e-12)
    assert_allclose(vs, [5.0, 20.0, 10.0, 0.0], atol=1e-12)
    assert_allclose(a, [0.5, -1.0, -1.0, 0.0], atol=1e-12)


def test_speed_at_position_starts_a_train_at_rest_and_is_zero_at_the_stop() -> None:
    ref = PlannedProfile(np.array([0.0, 100.0, 200.0]), np.array([0.0, 10.0, 0.0]))
    assert ref.speed_at_position(np.array([0.0]))[0] == pytest.approx(0.5)
    assert ref.speed_at_position(np.array([200.0, 250.0])).tolist() == [0.0, 0.0]


@pytest.mark.parametrize(
    ("x", "v", "field"),
    [
        ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0], "reference.x_m"),
        ([0.0, 1.0], [1.0, 1.0], "reference.v_mps"),
        ([0.0, 1.0, 2.0, 3.0], [0.0, 0.0, 1.0, 0.0], "reference.v_mps"),
    ],
)
def test_bad_tables_name_the_field(x, v, field) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ConfigError) as err:
        PlannedProfile(np.array(x), np.array(v))
    assert err.value.field == field
