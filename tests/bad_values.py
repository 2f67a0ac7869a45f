"""The bad values every constructor's argument check is tried with (tests/control/
test_constructor_inputs.py for the controllers, tests/test_model_constructor_inputs.py for
the physical models)."""

from __future__ import annotations

import numpy as np

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
