"""Our Mamdani engine against scikit-fuzzy, and the fuzzy controllers' behaviour."""

import numpy as np
import pytest
import skfuzzy as fuzz
from numpy.testing import assert_allclose

from railpilot.control.fuzzy import (
    RULES_DKI,
    RULES_DKP,
    RULES_FUZZY,
    SETS3,
    SETS4,
    FuzzyController,
    FuzzyPI,
    fis_eval,
    pack_fis,
    rule_indices,
    triangles,
)
from railpilot.control.pid import PID

N_GRID = 51
IN_ABC = triangles(-1.0, 1.0, 4)


def _skfuzzy_system(rules, out_sets, out_lo, out_hi):
    """The same rule base and membership functions, evaluated with scikit-fuzzy's
    membership functions, interpolation and centroid (skfuzzy.control needs networkx,
    which is not a dependency; the primitives are what it calls)."""
    grid_in = np.linspace(-1.0, 1.0, 601)  # contains every triangle vertex: exact fuzzification
    in_mf = [fuzz.trimf(grid_in, abc) for abc in IN_ABC]
    universe = np.linspace(out_lo, out_hi, N_GRID)
    out_abc = triangles(out_lo, out_hi, len(out_sets))
    out_mf = {name: fuzz.trimf(universe, abc) for name, abc in zip(out_sets, out_abc, strict=True)}

    def infer(x1, x2):
        mu1 = [fuzz.interp_membership(grid_in, mf, x1) for mf in in_mf]
        mu2 = [fuzz.interp_membership(grid_in, mf, x2) for mf in in_mf]
        agg = np.zeros_like(universe)
        for i in range(4):
            for j in range(4):
                w = np.fmin(mu1[i], mu2[j])  # AND = min
                agg = np.fmax(agg, np.fmin(w, out_mf[rules[i][j]]))  # clip, then max
        return fuzz.defuzz(universe, agg, "centroid")

    ours = pack_fis(IN_ABC, IN_ABC, rule_indices(rules, out_sets), out_abc, out_lo, out_hi, N_GRID)
    return infer, ours


@pytest.mark.parametrize(
    ("rules", "out_sets", "lo", "hi"),
    [(RULES_FUZZY, SETS4, -1.0, 1.0), (RULES_DKP, SETS3, 0.0, 1.0), (RULES_DKI, SETS3, 0.0, 1.0)],
    ids=["table1-current", "table2-dkp", "table3-dki"],
)
def test_inference_agrees_with_scikit_fuzzy(rules, out_sets, lo, hi):
    sim, ours = _skfuzzy_system(rules, out_sets, lo, hi)
    rng = np.random.default_rng(2020)
    x = rng.uniform(-1.0, 1.0, (1000, 2))
    x[:8] = [[-1, -1], [1, 1], [0, 0], [1 / 3, -1 / 3], [-1, 1], [1, -1], [0.5, 0.0], [0.0, 0.5]]
    scratch = np.zeros(8)
    mine, theirs = [], []
    for x1, x2 in x:
        theirs.append(sim(x1, x2))
        mine.append(fis_eval(ours, x1, x2, scratch))
    assert_allclose(mine, theirs, rtol=0, atol=1e-6 * (hi - lo))


def test_fuzzy_controller_is_monotone_in_the_error_and_scaled():
    c = FuzzyController(100.0, 1000.0, 50.0)
    outs = []
    for e in np.linspace(-300, 300, 61):
        c.reset()
        outs.append(c.update(e, 0.0, 1e-3))
    assert np.all(np.diff(outs) >= -1e-12)
    # e = PB with ce = 0 fires PB at 0.5 (ce is half NS, half PS): a large positive command
    assert 0.7 * 50.0 < outs[-1] < 50.0 * 7 / 9 + 1e-9
    assert_allclose(outs[30], 0.0, atol=1e-9)
    assert set(c.components) == {"e", "ce", "y", "u"}


def test_fuzzy_pi_gains_follow_the_tables_and_reuse_pid():
    c = FuzzyPI(2.0, 0.5, 1.0, 0.2, 100.0, 1000.0, ce_filter_s=0.0)
    c.update(100.0, 0.0, 1e-3)  # e = PB, ce = 0 (first sample): dKp = B, dKi ~ M/B mix
    comp = c.components
    assert comp["kp"] == pytest.approx(2.0 + 5 / 6, rel=1e-2)  # B fully fired
    assert 0.5 < comp["ki"] < 0.7
    # with the corrections frozen the law is a plain PI: compare with our PID kernel
    pid = PID(comp["kp"], comp["ki"])
    pid.update(100.0, 0.0, 1e-3)
    assert_allclose(comp["p"], pid.components["p"])


def test_reset_forgets_history_but_keeps_configuration():
    c = FuzzyPI(2.0, 0.5, 1.0, 0.2, 100.0, 1000.0)
    first = c.update(10.0, 0.0, 1e-3)
    c.update(20.0, 0.0, 1e-3)
    c.reset()
    assert c.update(10.0, 0.0, 1e-3) == first


def test_bad_scaling_is_rejected():
    with pytest.raises(ValueError, match="e_scale"):
        FuzzyController(0.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="dt"):
        FuzzyController(1.0, 1.0, 1.0).update(0.0, 0.0, 0.0)
