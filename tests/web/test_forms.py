"""The TSR form's schema: the dispatcher's units in, a LineTsr out, an error per field."""

from __future__ import annotations

import pytest

from railpilot.line.loader import load_line
from railpilot.line.model import RailLine
from railpilot.units import kmh_to_mps
from railpilot.web.forms import TsrFormError, parse_tsr_form
from railpilot.web.source import TSR_FORM_FIELDS

NOW_S = 1_000_000.0
GOOD = {
    "start_km": "12.5",
    "end_km": 14,
    "limit_kmh": "45",
    "valid_from_min": "",
    "valid_until_min": "60",
    "reason": " track work ",
}


@pytest.fixture(scope="module")
def line() -> RailLine:
    return load_line("heavy-haul")


def _errors(line: RailLine, **change: object) -> dict[str, str]:
    with pytest.raises(TsrFormError) as caught:
        parse_tsr_form({**GOOD, **change}, line=line, session=3, actor="d1", now_s=NOW_S)
    return caught.value.errors


def test_the_form_fields_are_those_of_a_line_tsr_in_the_dispatchers_units(line: RailLine) -> None:
    assert set(GOOD) == set(TSR_FORM_FIELDS)
    tsr = parse_tsr_form(GOOD, line=line, session=3, actor="d1", now_s=NOW_S)
    assert (tsr.session, tsr.start_m, tsr.end_m) == (3, 12_500.0, 14_000.0)
    assert tsr.limit_mps == pytest.approx(kmh_to_mps(45.0))
    assert (tsr.valid_from_s, tsr.valid_until_s) == (NOW_S, NOW_S + 3600.0)  # blank: now
    assert (tsr.reason, tsr.set_by) == ("track work", "d1")


def test_every_bad_field_is_reported_at_once(line: RailLine) -> None:
    errors = _errors(line, start_km="x", limit_kmh=True, valid_until_min="nan", reason=None)
    assert set(errors) == {"start_km", "limit_kmh", "valid_until_min", "reason"}
    assert errors["limit_kmh"].startswith("True is not allowed")  # a bool is not a number


def test_km_posts_must_lie_on_the_line(line: RailLine) -> None:
    errors = _errors(line, start_km="-1", end_km="590.5")
    assert "km post on line heavy-haul, 0 to 590" in errors["start_km"]
    assert set(errors) == {"start_km", "end_km"}


@pytest.mark.parametrize(
    ("change", "field", "message"),
    [
        (
            {"end_km": "12.5"},
            "end_km",
            "12.5 is not allowed: expected a km post above start_km = 12.5",
        ),
        (
            {"limit_kmh": "400"},
            "limit_kmh",
            "400 is not allowed: expected a speed above 0 and at most 360 km/h",
        ),
        (
            {"valid_until_min": "0"},
            "valid_until_min",
            "0 is not allowed: expected more minutes than valid_from_min = 0, and more than 0 "
            "(the end of a TSR lies ahead)",
        ),
    ],
)
def test_line_tsr_errors_speak_the_forms_units(
    line: RailLine, change: dict[str, str], field: str, message: str
) -> None:
    assert _errors(line, **change) == {field: message}
