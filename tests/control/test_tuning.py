"""Tuning rules (railpilot.control.tuning): SIMC formulas and closed-loop sanity."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

import control
from railpilot.control.tuning import simc_pid_integrating, smarc_from_simc

# paper 000 brake: delay 0.3 s, cylinder lag 0.65 s; speed loop k = 1 (u in m/s^2)
THETA, LAG = 0.3, 0.65


def test_simc_default_tau_c_case_by_hand():
    # tau_c = theta = 0.3: Kc = 1 / 0.6, tau_I = 2.4, tau_D = 0.65 (series form);
    # parallel: ki = Kc / tau_I, kd = Kc tau_D, kp = Kc (1 + tau_D / tau_I)
    gains = simc_pid_integrating(1.0, THETA, LAG)
    kc, tau_i, tau_d = 1.0 / 0.6, 2.4, 0.65
    assert_allclose(
        [gains["kp"], gains["ki"], gains["kd"], gains["derivative_filter_s"]],
        [kc * (1 + tau_d / tau_i), kc / tau_i, kc * tau_d, tau_d / (1 + tau_d / tau_i) / 10],
        rtol=1e-14,
    )


def test_parallel_form_equals_series_form():
    # kd s^2 + kp s + ki == Kc (tau_I s + 1)(tau_D s + 1) / tau_I for any tau_c
    k, tau_c = 2.0, 0.4
    g = simc_pid_integrating(k, THETA, LAG, tau_c_s=tau_c)
    kc, tau_i = 1.0 / (k * (tau_c + THETA)), 4.0 * (tau_c + THETA)
    series = kc / tau_i * np.polymul([tau_i, 1.0], [LAG, 1.0])
    assert_allclose([g["kd"], g["kp"], g["ki"]], series, rtol=1e-14)


def test_gain_scales_inversely_with_process_gain():
    g1 = simc_pid_integrating(1.0, THETA, LAG)
    g2 = simc_pid_integrating(2.0, THETA, LAG)
    assert_allclose([g2["kp"], g2["ki"], g2["kd"]], [g1["kp"] / 2, g1["ki"] / 2, g1["kd"] / 2])


def test_simc_pid_closes_a_stable_loop_with_margin():
    # plant exp(-0.3 s) / (s (0.65 s + 1)), delay as a 5th-order Pade (python-control)
    g = simc_pid_integrating(1.0, THETA, LAG)
    s = control.tf("s")
    pid = g["kp"] + g["ki"] / s + g["kd"] * s / (g["derivative_filter_s"] * s + 1)
    plant = control.tf(*control.pade(THETA, 5)) / (s * (LAG * s + 1))
    loop = pid * plant
    assert np.all(control.poles(control.feedback(loop, 1)).real < 0)
    gain_margin, phase_margin = control.stability_margins(loop)[:2]
    # SIMC "tight" tuning: the rule's design margins are GM ~ 3, PM ~ 47 deg for the
    # PI case; the derivative filter costs a few degrees
    assert gain_margin > 2.0
    assert phase_margin > 40.0


def test_smarc_from_simc_matches_the_pi_rule():
    # theta_eff = 0.95: tau_c = 0.95, Kc = 1 / 1.9, tau_I = 7.6; c = 1 / tau_I, ks = Kc - c
    g = smarc_from_simc(1.0, THETA, LAG)
    assert g["c"] == pytest.approx(1.0 / 7.6, rel=1e-14)
    assert g["ks"] + g["c"] == pytest.approx(1.0 / 1.9, rel=1e-14)


def test_smarc_from_simc_tighter_tau_c_gives_higher_gains():
    loose = smarc_from_simc(1.0, THETA, LAG)
    tight = smarc_from_simc(1.0, THETA, LAG, tau_c_s=0.25 * (THETA + LAG))
    assert tight["ks"] > loose["ks"]
    assert tight["c"] > loose["c"]
