"""The dispatcher's operations: one schema, the dispatcher's units in, an error per field."""

from __future__ import annotations

import pytest

from railpilot.ground.operations import (
    FIELDS,
    CancelTsr,
    ClearRestriction,
    OperationError,
    SendDispatch,
    SendTarget,
    SetRestriction,
    SetTsr,
    Status,
    parse_operation,
)
from railpilot.line.loader import load_line
from railpilot.line.model import UP, RailLine
from railpilot.link.messages import TargetReason
from railpilot.units import kmh_to_mps
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


def _errors(line: RailLine, op: str = "tsr_set", **change: object) -> dict[str, str]:
    fields = {**GOOD, **change} if op == "tsr_set" else change
    with pytest.raises(OperationError) as caught:
        parse_operation(op, fields, line=line, now_s=NOW_S)
    return caught.value.errors


def test_the_dashboards_form_has_the_fields_of_tsr_set() -> None:
    required, optional = FIELDS["tsr_set"]
    assert set(TSR_FORM_FIELDS) <= set(required + optional)
    assert set(required) <= set(TSR_FORM_FIELDS)


def test_a_tsr_in_the_dispatchers_units_becomes_si_on_the_ground_clock(line: RailLine) -> None:
    op = parse_operation("tsr_set", GOOD, line=line, now_s=NOW_S)
    assert isinstance(op, SetTsr)
    assert (op.start_m, op.end_m) == (12_500.0, 14_000.0)
    assert op.limit_mps == pytest.approx(kmh_to_mps(45.0))
    assert (op.valid_from_s, op.valid_until_s) == (NOW_S, NOW_S + 3600.0)  # blank: now
    assert (op.reason, op.session, op.trains) == ("track work", None, ())
    tsr = op.line_tsr(3, "d1")
    assert (tsr.session, tsr.set_by, tsr.valid_until_s) == (3, "d1", NOW_S + 3600.0)


def test_the_admin_port_and_the_cli_may_name_a_session_and_trains(line: RailLine) -> None:
    op = parse_operation(
        "tsr_set", {**GOOD, "session": "7", "trains": "1001, 1002 1001"}, line=line, now_s=NOW_S
    )
    assert isinstance(op, SetTsr)
    assert (op.session, op.trains) == (7, (1001, 1002))  # a form's text, duplicates once


def test_every_bad_field_is_reported_at_once(line: RailLine) -> None:
    errors = _errors(line, start_km="x", limit_kmh=True, valid_until_min="nan", reason=None)
    assert set(errors) == {"start_km", "limit_kmh", "valid_until_min", "reason"}
    assert errors["limit_kmh"].startswith("True is not allowed")  # a bool is not a number
    assert errors["reason"].startswith("required")


def test_km_posts_must_lie_on_the_line(line: RailLine) -> None:
    errors = _errors(line, start_km="-1", end_km="590.5")
    assert "km post on line heavy-haul, 0 to 590" in errors["start_km"]
    assert set(errors) == {"start_km", "end_km"}


def test_an_unknown_or_misspelt_field_is_an_error_not_ignored(line: RailLine) -> None:
    errors = _errors(line, valid_s=600)  # the admin port's old field
    assert errors == {
        "valid_s": "'valid_s' is not a field of tsr_set: expected only start_km, end_km, "
        "limit_kmh, valid_until_min, reason, valid_from_min, session, trains"
    }


@pytest.mark.parametrize(
    ("change", "field", "message"),
    [
        (
            {"end_km": "12.5"},
            "end_km",
            "12.5 is not allowed: expected a km post at least 1 cm above start_km = 12.5",
        ),
        (
            {"end_km": "12.500001"},  # the same km post on the wire (whole cm)
            "end_km",
            "12.500001 is not allowed: expected a km post at least 1 cm above start_km = 12.5",
        ),
        (
            {"limit_kmh": "400"},
            "limit_kmh",
            "400 is not allowed: expected a speed in km/h, 0 to 360",
        ),
        (
            {"limit_kmh": 0},
            "limit_kmh",
            "0 is not allowed: expected a speed above 0 and at most 360 km/h",
        ),
        (
            {"valid_until_min": "0"},
            "valid_until_min",
            "0 is not allowed: expected more "
            "minutes than valid_from_min = 0 (the end of a TSR lies ahead)",
        ),
        (
            {"session": 0},
            "session",
            "0 is not allowed: expected a TSR session number, an integer in [1, 4294967295]",
        ),
        (
            {"trains": [1, "x"]},
            "trains",
            "[1, 'x'] is not allowed: expected a list of train ids in [1, 4294967295]",
        ),
    ],
)
def test_each_rule_names_the_field_the_value_and_what_is_allowed(
    line: RailLine, change: dict[str, object], field: str, message: str
) -> None:
    assert _errors(line, **change) == {field: message}


def test_an_unknown_operation_names_the_allowed_ones(line: RailLine) -> None:
    errors = _errors(line, "reboot")
    assert errors == {
        "op": "'reboot' is not allowed: expected one of tsr_set, tsr_cancel, restriction_set, "
        "restriction_clear, target, dispatch, status"
    }


def test_the_other_operations(line: RailLine) -> None:
    def parse(op: str, **fields: object) -> object:
        return parse_operation(op, fields, line=line, now_s=NOW_S)

    assert parse("tsr_cancel", session=7) == CancelTsr(7)
    assert parse("status") == Status()
    assert parse("restriction_clear", id="2") == ClearRestriction(2)
    block = line.block_sections[3]
    op = parse("restriction_set", block=block.id, reason="section-fault")
    assert isinstance(op, SetRestriction)
    assert op.restriction.block_id == block.id
    assert op.restriction.reason is TargetReason.SECTION_FAULT
    span = parse(
        "restriction_set", start_km=100, end_km=101, track="up", reason="switch_indication_lost"
    )
    assert isinstance(span, SetRestriction)
    assert (span.restriction.start_m, span.restriction.end_m) == (100_000.0, 101_000.0)
    assert span.restriction.direction is UP
    assert parse("target", trains=[5], km=20) == SendTarget((5,), 20_000.0, TargetReason.OTHER)
    assert parse("dispatch", trains="all", text=" go ") == SendDispatch((), "go", None)


@pytest.mark.parametrize(
    ("op", "fields", "field"),
    [
        ("tsr_cancel", {}, "session"),
        ("restriction_set", {"reason": "section_fault"}, "block"),
        ("restriction_set", {"reason": "train_ahead", "block": "x"}, "reason"),
        ("restriction_set", {"reason": "section_fault", "block": "nope"}, "block"),
        ("restriction_set", {"reason": "section_fault", "start_km": 5, "end_km": 4}, "end_km"),
        ("target", {"km": 5}, "trains"),
        ("target", {"trains": "all", "km": 5}, "trains"),  # a target goes to named trains
        ("dispatch", {"trains": "all", "text": "x" * 1001}, "text"),
        ("dispatch", {"trains": "all"}, "text"),
    ],
)
def test_bad_requests_of_the_other_operations(
    line: RailLine, op: str, fields: dict[str, object], field: str
) -> None:
    assert field in _errors(line, op, **fields)


def test_the_operations_words_are_the_link_s_and_the_ground_s() -> None:
    """The operations' model (railpilot.schema, which may not import the link or the
    ground) writes the reasons, the tracks and the 32-bit bound out: they are these."""
    from railpilot.ground.targets import DECLARED_REASONS as GROUND_DECLARED
    from railpilot.link.messages import U32_MAX as LINK_U32_MAX
    from railpilot.schema import operations as schema

    assert tuple(r.name.lower() for r in GROUND_DECLARED) == schema.DECLARED_REASONS
    assert tuple(r.name.lower() for r in TargetReason) == schema.TARGET_REASONS
    assert schema.U32_MAX == LINK_U32_MAX
    assert set(schema.TRACKS) == {"up", "down", "both"}


def test_a_field_left_blank_in_a_form_is_a_field_left_out(line: RailLine) -> None:
    errors = _errors(line, reason="   ", valid_from_min="")
    assert errors == {"reason": "required: why the restriction is set, e.g. 'track work'"}
