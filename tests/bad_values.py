"""The bad values every constructor's argument check is tried with (tests/control/
test_constructor_inputs.py for the controllers, tests/test_model_constructor_inputs.py for
the physical models, tests/vehicle/test_consist.py for the consist).

``BAD`` names one value of each kind; ``KINDS`` draws other values of the same kind.
``every_bad_value`` turns a list of (target..., kind) cases into one property test: each
case runs once with BAD's own value as an explicit example, so every argument meets every
kind of bad value on every run, and Hypothesis then draws more values of each kind.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

#: (id, value): none of them is a valid value of any argument, except where a test's
#: ALLOWED says
BAD: list[tuple[str, object]] = [
    ("str", "x"),
    ("empty-str", ""),
    ("huge-int", 10**400),
    ("nan", float("nan")),
    ("inf", float("inf")),
    ("-inf", float("-inf")),
    ("-1e300", -1e300),
    ("None", None),
    ("True", True),
    ("np-bool", np.bool_(True)),
    ("pair", (1, 2)),
    ("None-str", [None, "x"]),
    ("huge-None", (10**400, None)),
    ("nan-pair", (float("nan"), 1.0)),
    ("long-list", list(range(10_000))),
    ("dict", {"a": 1}),
    ("complex", 1j),
]

_NAN = float("nan")
_INF = float("inf")
#: ints no float holds, of either sign
_HUGE_INTS = st.integers(min_value=10**309) | st.integers(max_value=-(10**309))
_NANS = st.sampled_from([_NAN, -_NAN, np.float64(_NAN), np.float32(_NAN)])
_FINITE = st.floats(allow_nan=False, allow_infinity=False)

#: id in BAD -> the values of that kind: each is as bad as BAD's own for any argument
#: that refuses BAD's (strings of digits and letters that name no choice, other NaNs,
#: NumPy's infinities, other ints too large for a float, lists as well as tuples ...)
KINDS: dict[str, st.SearchStrategy[Any]] = {
    "str": st.text(alphabet="0123456789.-xz", min_size=1, max_size=8),
    "empty-str": st.just(""),
    "huge-int": _HUGE_INTS,
    "nan": _NANS,
    "inf": st.sampled_from([_INF, np.float64(_INF), np.float32(_INF)]),
    "-inf": st.sampled_from([-_INF, np.float64(-_INF), np.float32(-_INF)]),
    "-1e300": st.floats(max_value=-1e300, allow_infinity=False)
    | st.floats(max_value=-1e300, allow_infinity=False).map(np.float64),
    "None": st.none(),
    # True only: False is what a flag such as a wagon's ``remote`` takes
    "True": st.just(True),
    "np-bool": st.just(np.bool_(True)),
    "pair": st.sampled_from([(1, 2), [1, 2]]),
    "None-str": st.permutations([None, "x"]) | st.permutations([None, "x"]).map(tuple),
    "huge-None": st.tuples(_HUGE_INTS, st.none()),
    "nan-pair": st.tuples(_NANS, _FINITE),
    "long-list": st.integers(1_000, 12_000).map(lambda n: list(range(n))),
    "dict": st.dictionaries(st.text(min_size=1, max_size=3), st.integers(), min_size=1),
    "complex": st.complex_numbers(allow_nan=False, allow_infinity=False),
}
assert list(KINDS) == [kind for kind, _ in BAD]

#: generated examples per property test, on top of one explicit example per case
EXAMPLES = 300


def every_bad_value(
    cases: Sequence[tuple[Any, ...]],
    bad: Sequence[tuple[str, object]] = BAD,
    kinds: dict[str, st.SearchStrategy[Any]] = KINDS,
) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Make ``test(case, value)`` a property test over ``cases``, each a tuple whose last
    item is a kind of ``bad``: ``value`` is of that kind. Every case runs once with the
    kind's own value in ``bad`` (an explicit example), then Hypothesis draws cases and
    values of their kind from ``kinds``."""
    own = dict(bad)
    assert set(kinds) == set(own), "a strategy for each kind of bad value"
    drawn = st.sampled_from(list(cases)).flatmap(
        lambda case: st.tuples(st.just(case), kinds[case[-1]])
    )

    def decorate(test: Callable[..., None]) -> Callable[..., None]:
        def check(pair: tuple[tuple[Any, ...], object]) -> None:
            test(*pair)

        check.__name__ = test.__name__
        check.__qualname__ = test.__qualname__
        check.__doc__ = test.__doc__
        check.__module__ = test.__module__
        run = given(pair=drawn)(check)
        for case in cases:
            run = example(pair=(case, own[case[-1]]))(run)
        return settings(max_examples=EXAMPLES, deadline=None)(run)

    return decorate
