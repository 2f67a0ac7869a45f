"""Torque table: bilinear interpolation against SciPy, CSV round trip, bad tables."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.interpolate import RegularGridInterpolator

from railpilot.eddy.table import TorqueTable, load_torque_table_csv, parse_torque_table_csv
from railpilot.eddy.torque_model import EddyBrakeParams, eddy_torque_at_speed_nm
from railpilot.errors import ConfigError


def test_bilinear_matches_scipy_regular_grid_interpolator():
    rng = np.random.default_rng(3)
    currents = np.sort(rng.uniform(0, 500, 12))
    speeds = np.sort(rng.uniform(0, 80, 9))
    torque = rng.uniform(0, 5000, (12, 9))
    table = TorqueTable(currents, speeds, torque)
    ref = RegularGridInterpolator((currents, speeds), torque, method="linear")
    pts = np.column_stack(
        [rng.uniform(currents[0], currents[-1], 1000), rng.uniform(speeds[0], speeds[-1], 1000)]
    )
    ours = np.array([table.torque(i, v) for i, v in pts])
    assert_allclose(ours, ref(pts), rtol=1e-12, atol=1e-9)


def test_inputs_outside_the_table_are_clamped_to_the_edges():
    table = TorqueTable(
        np.array([0.0, 10.0]), np.array([0.0, 1.0]), np.array([[0.0, 0.0], [5.0, 7.0]])
    )
    assert table.torque(50.0, 9.0) == 7.0
    assert table.torque(-1.0, 0.5) == 0.0


def test_model_table_is_close_to_the_analytic_model():
    table = TorqueTable.from_model()
    p = EddyBrakeParams()
    for i, v in [(300.0, 30.0), (411.3, 12.7), (366.6, 44.0)]:
        assert_allclose(table.torque(i, v), eddy_torque_at_speed_nm(i, v, p), atol=0.1)


def test_csv_round_trip(tmp_path):
    table = TorqueTable.from_model(max_current_a=50, current_step_a=10, speed_step_kmh=50)
    path = tmp_path / "t.csv"
    path.write_text(table.to_csv_text())
    back = load_torque_table_csv(path)
    assert_allclose(back.torque_nm, table.torque_nm, rtol=1e-9)
    assert_allclose(back.speeds_mps, table.speeds_mps, rtol=1e-9)


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("current_a,0,10\n0,0,0\n10,1,nan\n", "table.torque_nm[1, 1]"),
        ("current_a,0,10\n0,0,0\n0,1,2\n", "table.currents_a[1]"),
        ("current_a,10,0\n0,0,0\n5,1,2\n", "table.speeds_mps[1]"),
        ("current_a,0,10\n0,0,0\n", "csv: rows"),
        ("current_a,0,10\n0,0,0\n5,1\n", "csv: line 3"),
        ("current_a,0,10\n0,0,0\n5,1,x\n", "csv: line 3 column 3"),
        ("current_a,0,10\n0,0,0\n5,1,-2\n", "table.torque_nm[1, 1]"),
    ],
)
def test_bad_tables_name_the_problem(text, field):
    with pytest.raises(ConfigError) as info:
        parse_torque_table_csv(text)
    assert info.value.field == field


def test_wrong_shape_and_too_few_points():
    with pytest.raises(ConfigError, match="shape"):
        TorqueTable(np.array([0.0, 1.0]), np.array([0.0, 1.0, 2.0]), np.zeros((2, 2)))
    with pytest.raises(ConfigError, match="at least 2 points"):
        TorqueTable(np.array([0.0]), np.array([0.0, 1.0]), np.zeros((1, 2)))


def test_a_grid_too_large_to_build_is_refused_by_key() -> None:
    # 0.0001 A x 0.0001 km/h steps would ask for ~1.5e13 points: refused, not attempted
    with pytest.raises(ConfigError, match=r"table\.current_step_a"):
        TorqueTable.from_model(current_step_a=1e-4, speed_step_kmh=1e-4)
