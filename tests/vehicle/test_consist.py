"""The consist (railpilot.vehicle.consist): its checks, its arrays, and the point-mass train
it gives, against hand computation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from bad_values import BAD, every_bad_value
from railpilot.errors import ConfigError
from railpilot.scenario.consist_file import consist_preset
from railpilot.units import G_MPS2
from railpilot.vehicle.consist import (
    CONSIST_PRESETS,
    Consist,
    Vehicle,
    describe,
)
from railpilot.vehicle.traction import hxd1_locomotive
from railpilot.vehicle.train import MAX_LENGTH_M
from vehicle.consist_helpers import lead, train_of, wagon

# --- the point-mass train -----------------------------------------------------------------

wagon_params = st.fixed_dictionaries(
    {
        "mass_kg": st.floats(5e3, 300e3),
        "rotating_mass_factor": st.floats(0.0, 0.5),
        "length_m": st.floats(5.0, 30.0),
        "davis_a0": st.floats(0.0, 5.0),
        "davis_a1": st.floats(0.0, 0.05),
        "davis_a2": st.floats(0.0, 0.002),
        "service_brake_force_n": st.floats(1e3, 300e3),
    }
)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 300), params=wagon_params)
def test_point_mass_of_identical_wagons_behind_a_locomotive_is_the_hand_computation(n, params):
    consist = train_of(n, **params)
    train = consist.point_mass_train()
    loco = consist.vehicles[0]
    m_w, m_l = params["mass_kg"], loco.mass_kg
    total = m_l + n * m_w
    # by hand: masses add, effective masses add, specific resistances weigh by mass
    assert_allclose(train.mass_kg, total, rtol=1e-12)
    assert_allclose(train.length_m, loco.length_m + n * params["length_m"], rtol=1e-12)
    gamma = (m_l * loco.rotating_mass_factor + n * m_w * params["rotating_mass_factor"]) / total
    assert_allclose(train.rotating_mass_factor, gamma, rtol=1e-9, atol=1e-15)
    for key in ("davis_a0", "davis_a1", "davis_a2"):
        expected = (m_l * getattr(loco, key) + n * m_w * params[key]) / total
        assert_allclose(getattr(train, key), expected, rtol=1e-12, atol=1e-18)
    m_eff = m_l * (1 + loco.rotating_mass_factor) + n * m_w * (1 + params["rotating_mass_factor"])
    assert_allclose(
        train.max_service_decel_mps2, n * params["service_brake_force_n"] / m_eff, rtol=1e-12
    )
    # the locomotive's regenerative envelope is the point mass's electric brake
    assert train.electric_brake.max_force_n == loco.locomotive.regen.max_force_n
    assert train.motor_cars == 1


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 200), params=wagon_params)
def test_a_train_of_one_vehicle_type_keeps_that_vehicle_s_specific_values(n, params):
    """A lead with the wagons' own numbers: every specific value is the vehicle's own."""
    loco_params = params | {"distributor": "direct-release"}
    head = lead(**loco_params)
    consist = Consist("same", (head, *(wagon(f"W-{k}", **params) for k in range(n))))
    train = consist.point_mass_train()
    assert_allclose(train.mass_kg, (n + 1) * params["mass_kg"], rtol=1e-12)
    for key in ("rotating_mass_factor", "davis_a0", "davis_a1", "davis_a2"):
        assert_allclose(getattr(train, key), params[key], rtol=1e-12, atol=1e-15)
    assert_allclose(
        train.max_service_decel_mps2,
        params["service_brake_force_n"]
        / (params["mass_kg"] * (1 + params["rotating_mass_factor"])),
        rtol=1e-12,
    )


def test_davis_force_of_the_point_mass_is_the_sum_of_the_vehicles_forces():
    consist = consist_preset("heavy-haul-20kt-dp")
    train = consist.point_mass_train()
    v_kmh = np.linspace(0.0, 100.0, 11)
    davis = consist.davis()
    per_vehicle = (davis[:, :1] + davis[:, 1:2] * v_kmh + davis[:, 2:] * v_kmh**2) * (
        consist.masses_kg()[:, None] * G_MPS2 / 1000.0
    )
    whole = (train.davis_a0 + train.davis_a1 * v_kmh + train.davis_a2 * v_kmh**2) * (
        train.mass_kg * G_MPS2 / 1000.0
    )
    assert_allclose(whole, per_vehicle.sum(axis=0), rtol=1e-12)


def test_a_consist_without_any_friction_brake_has_no_point_mass_deceleration():
    consist = Consist("no brakes", (lead(), wagon(distributor="none", service_brake_force_n=0)))
    with pytest.raises(ConfigError, match="friction brake"):
        consist.point_mass_train()


# --- arrays -------------------------------------------------------------------------------


def test_arrays_positions_and_indices():
    lengths = [35.0, 12.0, 13.0, 35.0, 14.0]
    vehicles = (
        lead("L-1", length_m=lengths[0]),
        wagon("W-1", length_m=lengths[1]),
        wagon("W-2", length_m=lengths[2], distributor="graduated-release"),
        lead("L-2", length_m=lengths[3], remote=True),
        wagon("W-3", length_m=lengths[4], distributor="none", service_brake_force_n=0.0),
    )
    consist = Consist("c", vehicles)
    assert consist.n_vehicles == 5
    assert_allclose(consist.front_m(), [0.0, 35.0, 47.0, 60.0, 95.0])
    assert consist.length_m == sum(lengths)
    assert_array_equal(consist.locomotive_indices(), [0, 3])
    assert consist.locomotive_indices().dtype == np.int64
    assert_array_equal(consist.remote_indices(), [3])
    assert consist.remote_indices().dtype == np.int64
    assert_array_equal(consist.direct_release(), [False, True, False, False, False])
    assert_array_equal(consist.has_air_brake(), [False, True, True, False, False])
    assert consist.davis().shape == (5, 3)
    assert len(consist.draft_gears()) == 4
    assert_allclose(consist.service_brake_force_n(), [0.0, 50e3, 50e3, 0.0, 0.0])
    # a fresh array each call: a caller's change does not reach the consist
    consist.masses_kg()[0] = -1.0
    assert consist.masses_kg()[0] == vehicles[0].mass_kg


# --- checks ---------------------------------------------------------------------------------


def test_the_first_vehicle_must_be_the_lead_locomotive():
    with pytest.raises(ConfigError, match=r"consist\.vehicles\[0\]"):
        Consist("c", (wagon(), lead()))
    with pytest.raises(ConfigError, match="lead locomotive"):
        Consist("c", (lead(remote=True), wagon()))


def test_names_are_unique_and_the_train_not_too_long():
    with pytest.raises(ConfigError, match=r"vehicles\[2\]\.name"):
        Consist("c", (lead(), wagon("W"), wagon("W")))
    n = int(MAX_LENGTH_M // 100.0)  # 100 m wagons: the longest a vehicle may be
    Consist("c", (lead(length_m=35.0), *(wagon(f"W{k}", length_m=100.0) for k in range(n - 1))))
    with pytest.raises(ConfigError, match="length_m"):
        Consist("c", (lead(length_m=35.0), *(wagon(f"W{k}", length_m=100.0) for k in range(n))))


def test_a_vehicle_without_distributor_has_no_brake_force_and_only_locomotives_are_remote():
    with pytest.raises(ConfigError, match="service_brake_force_n"):
        wagon(distributor="none", service_brake_force_n=1.0)
    with pytest.raises(ConfigError, match="remote"):
        wagon(remote=True)
    with pytest.raises(ConfigError, match="locomotive"):
        wagon(locomotive=hxd1_locomotive())
    with pytest.raises(ConfigError, match="locomotive"):
        lead(locomotive=None)


VEHICLE_FIELDS = [f.name for f in dataclasses.fields(Vehicle)]
CONSIST_FIELDS = [f.name for f in dataclasses.fields(Consist)]
#: (field, bad-value id) that are valid after all: a name is any non-empty string, and a
#: wagon's locomotive is None (the default)
ALLOWED = {("name", "str"), ("locomotive", "None")}


@every_bad_value([(f, kind) for f in VEHICLE_FIELDS for kind, _ in BAD if (f, kind) not in ALLOWED])
def test_a_bad_vehicle_argument_gets_a_short_config_error_naming_it(case, value):
    field, _ = case
    with pytest.raises(ConfigError) as info:
        dataclasses.replace(wagon(), **{field: value})
    message = str(info.value)
    assert field in message
    assert len(message) < 400, message


@every_bad_value([(f, kind) for f in CONSIST_FIELDS for kind, _ in BAD if (f, kind) not in ALLOWED])
def test_a_bad_consist_argument_gets_a_short_config_error_naming_it(case, value):
    field, _ = case
    good = Consist("c", (lead(), wagon()))
    with pytest.raises(ConfigError) as info:
        dataclasses.replace(good, **{field: value})
    message = str(info.value)
    assert field in message
    assert len(message) < 400, message


# --- presets --------------------------------------------------------------------------------


def test_presets_by_name_and_an_unknown_name_lists_them():
    for name in CONSIST_PRESETS:
        consist = consist_preset(name)
        assert consist.name == name
        assert describe(consist)["vehicles"] == consist.n_vehicles
    with pytest.raises(ConfigError) as info:
        consist_preset("heavy-haul-30kt")
    for name in CONSIST_PRESETS:
        assert name in str(info.value)


def test_the_distributed_power_preset_has_its_remote_after_wagon_105():
    consist = consist_preset("heavy-haul-20kt-dp")
    assert_array_equal(consist.locomotive_indices(), [0, 106])
    assert_array_equal(consist.remote_indices(), [106])
    assert consist.vehicles[106].name == "HXD1-2"
    assert consist.vehicles[106].locomotive == hxd1_locomotive()
