"""Bad input to a controller's constructor or ``update``'s ``dt`` never crashes: it gets a
ValueError naming the argument, short enough to read. Valid edge values stay valid."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest
from hypothesis import strategies as st

from bad_values import BAD, KINDS, every_bad_value
from railpilot.control import base
from railpilot.control.fuzzy import FuzzyController, FuzzyPI
from railpilot.control.open_loop import OpenLoop
from railpilot.control.pid import PID, TrackingPID
from railpilot.control.pstop import PredictiveStop
from railpilot.control.qsmc import QSMC
from railpilot.control.smarc import SMARC

#: every controller class, with the fewest arguments that build it
BASE: dict[type, dict[str, object]] = {
    PID: {"kp": 1},
    TrackingPID: {"kp": 1},
    SMARC: {},
    QSMC: {"c": 1, "eps": 1, "q": 0.5, "zeta": 0.1, "Delta": 0.1, "T": 0.1},
    PredictiveStop: {"sigma": 1, "tau": 1},
    FuzzyController: {"e_scale": 1, "ce_scale": 1, "u_scale": 1},
    FuzzyPI: {"kp1": 1, "ki1": 1, "kp_span": 1, "ki_span": 1, "e_scale": 1, "ce_scale": 1},
    OpenLoop: {"level": 1},
}


#: (class, argument, id) of bad-looking values an argument legitimately takes
ALLOWED: set[tuple[type, str, str]] = {
    (QSMC, "tau_d", "inf"),  # no disturbance estimate
    (QSMC, "keep_q", "True"),
    (QSMC, "keep_q", "np-bool"),
    (PredictiveStop, "stop_m", "nan"),  # tracking only
    (SMARC, "gamma", "pair"),
    # any finite number: gains of either sign, a stop point, a constant command
    *((cls, gain, "-1e300") for cls in (PID, TrackingPID) for gain in ("kp", "ki", "kd")),
    (PredictiveStop, "stop_m", "-1e300"),
    (OpenLoop, "level", "-1e300"),
} | {(cls, "output_limits", "pair") for cls in BASE if cls is not OpenLoop}


def _arguments(cls: type) -> list[str]:
    names = [
        p.name
        for p in inspect.signature(cls).parameters.values()
        if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]
    if cls is TrackingPID:  # the rest go to PID through **kwargs
        names += [n for n in _arguments(PID) if n not in names]
    return names


def _default(cls: type, name: str) -> object:
    for klass in (cls, PID):
        p = inspect.signature(klass).parameters.get(name)
        if p is not None:
            return p.default
    return inspect.Parameter.empty


#: (class, argument, kind of bad value) the argument refuses: every pair but the allowed
CASES = [
    (cls, name, kind)
    for cls in BASE
    for name in _arguments(cls)
    for kind, value in BAD
    if (cls, name, kind) not in ALLOWED
    # None is what an optional argument defaults to (sigma_track, backcalc_gain, ...)
    and not (value is None and _default(cls, name) is None)
]


@every_bad_value(CASES)
def test_bad_argument_gets_a_short_value_error_naming_it(case, value):
    cls, name, _ = case
    with pytest.raises(ValueError) as info:
        cls(**(BASE[cls] | {name: value}))
    message = str(info.value)
    assert name in message
    assert len(message) < 300, message


@pytest.mark.parametrize(
    ("cls", "name", "value_id"), sorted(ALLOWED, key=lambda c: (c[0].__name__, c[1], c[2]))
)
def test_allowed_special_values_stay_allowed(cls, name, value_id):
    value = dict(BAD)[value_id]
    ctl = cls(**(BASE[cls] | {name: value}))
    _run(cls, ctl)


def test_huge_int_is_written_short():
    with pytest.raises(ValueError, match=r"^ks = 1\.000e\+400 is not allowed"):
        SMARC(ks=10**400)
    with pytest.raises(ValueError, match=r"gamma1 = 1\.000e\+400 is not allowed"):
        SMARC(gamma=(10**400, 0.0))
    with pytest.raises(ValueError, match=r"^output_limits\[0\] = 1\.000e\+400 is not allowed"):
        PID(1.0, output_limits=(10**400, None))


# --- update's dt ----------------------------------------------------------------------

BAD_DT: list[tuple[str, object]] = [
    ("str", "x"),
    ("huge-int", 10**400),
    ("nan", float("nan")),
    ("np-nan", np.float64("nan")),
    ("inf", float("inf")),
    ("None", None),
    ("negative", -1.0),
    ("zero", 0.0),
    ("zero-int", 0),
    ("True", True),
    ("pair", (0.1, 0.1)),
]

#: the values of each kind of bad dt
DT_KINDS: dict[str, st.SearchStrategy[object]] = {
    "str": KINDS["str"],
    "huge-int": KINDS["huge-int"],
    "nan": KINDS["nan"],
    "np-nan": st.just(np.float64("nan")),
    "inf": KINDS["inf"] | KINDS["-inf"],
    "None": st.none(),
    "negative": st.floats(max_value=-1e-300, allow_infinity=False)
    | st.integers(max_value=-1)
    | st.integers(min_value=-(2**63), max_value=-1).map(np.int64),
    "zero": st.sampled_from([0.0, -0.0, np.float64(0.0), np.float32(0.0)]),
    "zero-int": st.sampled_from([0, np.int64(0), np.uint8(0)]),
    "True": st.booleans() | st.booleans().map(np.bool_),
    "pair": st.tuples(st.floats(0.001, 1.0), st.floats(0.001, 1.0))
    | st.lists(st.floats(0.001, 1.0), min_size=1, max_size=3),
}


def _reference(cls: type) -> object:
    return (1.0, 1.0, 0.0) if cls in (TrackingPID, SMARC, QSMC, PredictiveStop) else 1.0


def _measurement(cls: type) -> object:
    return (1.0, 1.0) if cls in (TrackingPID, SMARC, QSMC, PredictiveStop) else 1.0


def _run(cls: type, ctl: object, dt: object = 0.01) -> float:
    out = ctl.update(_reference(cls), _measurement(cls), dt)  # type: ignore[attr-defined]
    assert math.isfinite(out)
    return out


@every_bad_value([(cls, kind) for cls in BASE for kind, _ in BAD_DT], BAD_DT, DT_KINDS)
def test_bad_dt_gets_a_short_value_error_naming_it(case, dt):
    cls, _ = case
    ctl = cls(**BASE[cls])
    with pytest.raises(ValueError, match=r"^dt = ") as info:
        ctl.update(_reference(cls), _measurement(cls), dt)
    assert len(str(info.value)) < 300


@pytest.mark.parametrize("cls", list(BASE), ids=lambda c: c.__name__)
@pytest.mark.parametrize("dt", [0.01, np.float64(0.01), np.float32(0.01), 1, np.int64(1)])
def test_numpy_and_int_dt_are_accepted(cls, dt):
    _run(cls, cls(**BASE[cls]), dt)


# --- valid edge values --------------------------------------------------------------


#: (class, argument) of a gain that takes 0.5 and 2
GAINS = [
    (PID, "kp"),
    (PID, "ki"),
    (TrackingPID, "position_gain"),
    (SMARC, "ks"),
    (SMARC, "c"),
    (QSMC, "c"),
    (QSMC, "sigma"),
    (PredictiveStop, "speed_gain"),
    (PredictiveStop, "sigma_track"),
    (FuzzyController, "u_scale"),
    (FuzzyPI, "kp1"),
    (OpenLoop, "level"),
]


@pytest.mark.parametrize(("cls", "name"), GAINS, ids=lambda v: getattr(v, "__name__", v))
@pytest.mark.parametrize(
    "value", [np.float64(0.5), np.float32(0.5), np.int64(2), np.uint8(2), 2], ids=repr
)
def test_numpy_scalars_are_numbers(cls, name, value):
    ours = cls(**(BASE[cls] | {name: value}))
    plain = cls(**(BASE[cls] | {name: float(value)}))
    assert _run(cls, ours) == _run(cls, plain)
    assert ours.params.dtype == np.float64


@pytest.mark.parametrize("cls", [c for c in BASE if c is not OpenLoop], ids=lambda c: c.__name__)
@pytest.mark.parametrize(
    "limits",
    [
        (None, None),
        (None, 0.5),
        (-0.5, None),
        [-1, 1],
        (np.float64(-1.0), np.int64(1)),
        (float("-inf"), float("inf")),
        np.array([-1.0, 1.0]),
    ],
    ids=repr,
)
def test_output_limits_take_none_and_numpy_entries(cls, limits):
    _run(cls, cls(**(BASE[cls] | {"output_limits": limits})))


def test_other_edge_values_are_accepted():
    QSMC(**(BASE[QSMC] | {"tau_d": float("inf"), "keep_q": False}))
    QSMC(**(BASE[QSMC] | {"tau_d": np.float64(2.0), "keep_q": np.bool_(False)}))
    PredictiveStop(sigma=1, tau=1, stop_m=float("nan"), sigma_track=None, davis_mps2=[0, 0, 0])
    PredictiveStop(sigma=np.float64(1), tau=np.int64(1), davis_mps2=np.array([0.01, 0.0, 1e-4]))
    PID(1, derivative_filter_s=0, backcalc_gain=None, anti_windup="backcalc")
    PID(1, backcalc_gain=np.float64(0.0), anti_windup="backcalc")
    assert FuzzyController(1, 1, 1, n_grid=np.int64(5)).n_grid == 5
    assert FuzzyPI(1, 0, 1, 0, 1, 1, n_grid=3).n_grid == 3
    SMARC(gamma=np.array([0.1, 0.1]), theta0=[1, 0], theta_bounds=np.array([[0.5, 2], [-1, 1]]))
    SMARC(phi=0, alpha=np.float32(0.1), output_limits=(-1.0, None))


# --- the shared checks ------------------------------------------------------------------


def test_check_number():
    assert base.check_number("k", np.int64(3)) == 3.0
    assert type(base.check_number("k", np.float32(0.5))) is float
    assert base.check_number("t", float("inf"), positive=True, allow_inf=True) == math.inf
    assert math.isnan(base.check_number("x", float("nan"), allow_nan=True))
    with pytest.raises(
        ValueError, match=r"^k = 0 is not allowed: expected a finite number > 0 \[s\]$"
    ):
        base.check_number("k", 0, positive=True, unit="s")
    with pytest.raises(
        ValueError, match=r"^k = -1\.0 is not allowed: expected a finite number >= 0$"
    ):
        base.check_number("k", -1.0, minimum=0.0)
    with pytest.raises(ValueError, match=r"^k = 'x' is not allowed"):
        base.check_number("k", "x")
    with pytest.raises(ValueError, match=r"^t = -inf is not allowed"):
        base.check_number("t", float("-inf"), positive=True, allow_inf=True)


def test_check_count():
    assert base.check_count("n", np.int64(5), 3, 10) == 5
    for bad in (2, 11, 5.0, "5", True, None, 10**400, float("nan")):
        with pytest.raises(ValueError, match=r"^n = .* expected a whole number from 3 to 10$"):
            base.check_count("n", bad, 3, 10)


def test_check_limits_and_dt():
    assert base.check_limits((None, 1)) == (-math.inf, 1.0)
    for bad in (None, 1.0, (1.0,), (1, 2, 3), "ab", (1.0, 1.0)):
        with pytest.raises(ValueError, match=r"^output_limits"):
            base.check_limits(bad)  # type: ignore[arg-type]
    assert base.check_dt(0.5) == 0.5
    assert base.check_dt(np.float64(0.5)) == 0.5
    with pytest.raises(ValueError, match=r"^dt = 'x' is not allowed"):
        base.check_dt("x")  # type: ignore[arg-type]
