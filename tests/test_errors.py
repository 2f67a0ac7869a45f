"""railpilot.errors: what every check of a number starts from."""

import math

import numpy as np
import pytest

from railpilot.errors import is_finite_number


@pytest.mark.parametrize(
    "value",
    [0, -3, 10**30, 0.0, -2.5, 1e308, np.float64(4.0), 5e-324],
)
def test_finite_ints_and_floats_are_numbers(value):
    assert is_finite_number(value)


@pytest.mark.parametrize(
    "value",
    [
        math.nan,
        math.inf,
        -math.inf,
        np.float64("nan"),
        np.float64("inf"),
        True,
        False,
        "1.0",
        None,
        [1.0],
        1 + 0j,
        np.array(1.0),
    ],
)
def test_nan_inf_bools_and_non_numbers_are_not(value):
    assert not is_finite_number(value)


# --- values in messages ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "length"),
    [("x" * 5000, 5002), (list(range(3000)), 16890), (b"\x01" * 2000, 8003)],
)
def test_a_long_value_is_shown_by_its_start_and_its_length(value, length):
    from railpilot.errors import MAX_SHOWN_CHARS, ConfigError
    from railpilot.link.errors import LinkConfigError

    assert len(repr(value)) == length
    for error in (ConfigError("name", value, "a name"), LinkConfigError("name", value, "a name")):
        text = str(error)
        assert f"... ({length:,} characters) is not allowed" in text
        assert repr(value)[:100] in text
        assert len(text) < MAX_SHOWN_CHARS + 120


def test_a_short_value_is_shown_whole():
    from railpilot.errors import ConfigError

    value = "y" * 150
    assert (
        str(ConfigError("name", value, "a name"))
        == f"name = {value!r} is not allowed: expected a name"
    )


def test_an_operations_long_text_is_cut_and_a_long_number_written_short():
    from railpilot.ground.operations import OperationError, parse_operation
    from railpilot.line.loader import load_line

    line = load_line("metro")
    fields = {"start_km": "1" + "0" * 400, "end_km": 16.0, "limit_kmh": 40, "reason": "r" * 3000}
    fields["valid_until_min"] = 60
    with pytest.raises(OperationError) as caught:
        parse_operation("tsr_set", fields, line=line, now_s=0.0)
    errors = caught.value.errors
    assert errors["start_km"].startswith("1.000e+400 is not allowed")
    assert "(3,002 characters)" in errors["reason"] and len(errors["reason"]) < 400


def test_a_container_holding_a_number_past_reprs_limit_is_named_not_written():
    """repr refuses an int of more than 4,300 digits: shown says what the value is."""
    from railpilot.errors import ConfigError, shown

    huge = 10**5000
    assert shown(huge) == "1.000e+5000"
    assert shown([1, huge]) == "<a list holding a number too long to write out>"
    text = str(ConfigError("train.davis", (huge, 0), "three numbers"))
    assert text == (
        "train.davis = <a tuple holding a number too long to write out> is not allowed: "
        "expected three numbers"
    )
