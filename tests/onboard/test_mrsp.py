"""Most restrictive speed profile (railpilot.onboard.mrsp).

Properties against a brute-force pointwise minimum of the inputs (hypothesis), hand cases
with exact values, the train-length extension against the link's own, and the errors.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from railpilot.errors import ConfigError
from railpilot.link.config import OnboardConfig
from railpilot.link.events import AppliedTsr
from railpilot.link.messages import RunningInfo, TargetPoint, TargetReason, TravelDirection, TsrSet
from railpilot.link.onboard import OnboardEndpoint
from railpilot.onboard.mrsp import (
    ActiveTsrs,
    Decrease,
    Governor,
    GovernorKind,
    Mrsp,
    SpeedProfile,
    TargetStop,
    apply_tsr,
    direction_sign,
    extend_tsr,
    km_post_m,
    most_restrictive_profile,
    travelled_m,
    tsr_in_force,
)

UP = TravelDirection.UP
DOWN = TravelDirection.DOWN
INF = math.inf
STATIC = Governor(GovernorKind.STATIC)


def tsr(
    session: int,
    zone_start_m: float,
    zone_end_m: float,
    limit_mps: float,
    valid_from_s: float = 0.0,
    valid_until_s: float = 1e9,
) -> AppliedTsr:
    """An applied TSR whose received stretch is its zone (extension already included)."""
    return AppliedTsr(
        session,
        zone_start_m,
        zone_end_m,
        zone_start_m,
        zone_end_m,
        limit_mps,
        valid_from_s,
        valid_until_s,
    )


def tsr_limit(t: AppliedTsr, x: np.ndarray) -> np.ndarray:
    """The TSR on its own: its limit on the closed zone, unrestricted elsewhere."""
    return np.where((t.zone_start_m <= x) & (x <= t.zone_end_m), t.limit_mps, INF)


def target_limit(t: TargetStop, x: np.ndarray, direction: TravelDirection) -> np.ndarray:
    """The target on its own: 0 from its position on in the direction of travel."""
    beyond = x >= t.position_m if direction is UP else x <= t.position_m
    return np.where(beyond, 0.0, INF)


def brute_force(
    static: SpeedProfile,
    tsrs: list[AppliedTsr],
    targets: list[TargetStop],
    direction: TravelDirection,
    x: np.ndarray,
) -> np.ndarray:
    limits = [static.at(x)]
    limits += [tsr_limit(t, x) for t in tsrs]
    limits += [target_limit(t, x, direction) for t in targets]
    return np.min(np.vstack(limits), axis=0)


def sample_points(*positions: float, extra: int = 0) -> np.ndarray:
    """Every position, each +- 1e-6, and a dense grid over their span."""
    p = np.asarray(positions, dtype=float)
    grid = np.linspace(p.min() - 50.0, p.max() + 50.0, 401 + extra)
    return np.unique(np.concatenate([p, p - 1e-6, p + 1e-6, grid]))


def beside(edges: np.ndarray, e: float) -> tuple[float, float]:
    """A probe inside the piece left of edge ``e`` and one inside the piece right of it.

    The middles of the neighbouring pieces (1 m outside at the ends), so that even pieces
    a few ulp long are probed inside (a piece one ulp long has no inside: the caller skips
    it with :func:`probed_inside`).
    """
    i = int(np.searchsorted(edges, e))
    left = (edges[i - 1] + e) / 2.0 if i > 0 else e - 1.0
    right = (e + edges[i + 1]) / 2.0 if i + 1 < len(edges) else e + 1.0
    return left, right


def probed_inside(edges: np.ndarray, e: float) -> bool:
    """Whether both :func:`beside` probes lie strictly inside their pieces."""
    left, right = beside(edges, e)
    return left < e < right and not np.isin([left, right], edges).any()


def inputs_positions(
    static: SpeedProfile, tsrs: list[AppliedTsr], targets: list[TargetStop]
) -> list[float]:
    out = list(static.edges_m)
    for t in tsrs:
        out += [t.zone_start_m, t.zone_end_m]
    out += [t.position_m for t in targets]
    return out


# ---------------------------------------------------------------------------- strategies

#: positions on a coarse grid (so boundaries often coincide) or anywhere
position = st.one_of(
    st.integers(0, 40).map(lambda k: 100.0 * k),
    st.floats(0.0, 4000.0, allow_nan=False),
)
speed = st.one_of(
    st.sampled_from([0.0, 5.0, 10.0, 12.5, 20.0, INF]),
    st.floats(0.0, 40.0, allow_nan=False),
)
directions = st.sampled_from([UP, DOWN])


@st.composite
def profiles(draw: st.DrawFn) -> SpeedProfile:
    edges = sorted(draw(st.sets(position, min_size=2, max_size=7)))
    speeds = draw(st.lists(speed, min_size=len(edges) - 1, max_size=len(edges) - 1))
    return SpeedProfile(edges, speeds)


@st.composite
def applied_tsrs(draw: st.DrawFn, session: st.SearchStrategy[int] | None = None) -> AppliedTsr:
    a, b = draw(position), draw(position)
    assume(a != b)
    s = draw(session if session is not None else st.integers(1, 6))
    return tsr(s, min(a, b), max(a, b), draw(speed.filter(math.isfinite)))


def unique_sessions(tsrs: list[AppliedTsr]) -> list[AppliedTsr]:
    by_session = {t.session: t for t in tsrs}
    return list(by_session.values())


tsr_lists = st.lists(applied_tsrs(), max_size=5).map(unique_sessions)
target_lists = st.lists(st.builds(TargetStop, position, st.integers(0, 9)), max_size=3)


# ---------------------------------------------------------------------------- properties


@settings(max_examples=300, deadline=None)
@given(profiles(), tsr_lists, target_lists, directions)
@pytest.mark.slow
def test_never_above_any_input(static, tsrs, targets, direction):
    mrsp = most_restrictive_profile(static, tsrs, targets, direction=direction)
    x = sample_points(*inputs_positions(static, tsrs, targets), *mrsp.edges_m)
    v = mrsp.at(x)
    assert np.all(v <= static.at(x))
    for t in tsrs:
        assert np.all(v <= tsr_limit(t, x))
    for t in targets:
        assert np.all(v <= target_limit(t, x, direction))


@settings(max_examples=300, deadline=None)
@given(profiles(), tsr_lists, target_lists, directions)
@pytest.mark.slow
def test_equals_the_pointwise_minimum_of_the_inputs(static, tsrs, targets, direction):
    mrsp = most_restrictive_profile(static, tsrs, targets, direction=direction)
    x = sample_points(*inputs_positions(static, tsrs, targets), extra=600)
    assert_array_equal(mrsp.at(x), brute_force(static, tsrs, targets, direction, x))


@settings(max_examples=300, deadline=None)
@given(profiles(), tsr_lists, target_lists, directions)
@pytest.mark.slow
def test_canonical_form(static, tsrs, targets, direction):
    mrsp = most_restrictive_profile(static, tsrs, targets, direction=direction)
    for edges in (mrsp.edges_m, mrsp.profile.edges_m, static.edges_m):
        assert np.all(np.diff(edges) > 0)  # no zero-length piece
    assert np.all(mrsp.profile.speeds_mps[1:] != mrsp.profile.speeds_mps[:-1])
    pieces = list(zip(mrsp.speeds_mps.tolist(), mrsp.governors, strict=True))
    assert all(a != b for a, b in itertools.pairwise(pieces))
    # the speed-only profile is the same function as the finer pieces
    assert mrsp.profile == SpeedProfile(mrsp.edges_m, mrsp.speeds_mps)
    # and the MRSP describes exactly the static profile's line
    assert (mrsp.edges_m[0], mrsp.edges_m[-1]) == (static.start_m, static.end_m)


@settings(max_examples=300, deadline=None)
@given(profiles(), tsr_lists, target_lists, directions)
@pytest.mark.slow
def test_at_an_edge_the_stricter_side_applies(static, tsrs, targets, direction):
    mrsp = most_restrictive_profile(static, tsrs, targets, direction=direction)
    edges = mrsp.profile.edges_m
    for e in edges[[probed_inside(edges, e) for e in edges]]:
        left, right = beside(edges, e)
        assert mrsp.at(e) == min(mrsp.at(left), mrsp.at(right))
    # the governor named at an edge is that of the stricter side (the entered one on a tie)
    edges = mrsp.edges_m
    for e in edges[[probed_inside(edges, e) for e in edges]]:
        left, right = beside(edges, e)
        behind, ahead = (left, right) if direction is UP else (right, left)
        g_behind, g_ahead = mrsp.governor_at([behind, ahead])
        v_behind, v_ahead = mrsp.at([behind, ahead])
        assert mrsp.governor_at(e) == [g_behind if v_behind < v_ahead else g_ahead]


@settings(max_examples=200, deadline=None)
@given(
    profiles(),
    tsr_lists,
    target_lists,
    directions,
    st.sampled_from([1e-9, 1e-6, 1e-3]),
    st.data(),
)
def test_tiny_perturbations_move_boundaries_but_make_no_spike(
    static, tsrs, targets, direction, eps, data
):
    signs = st.sampled_from([-1.0, 0.0, 1.0])
    moved_tsrs = []
    for t in tsrs:
        a = t.zone_start_m + data.draw(signs) * eps
        b = t.zone_end_m + data.draw(signs) * eps
        assume(a < b)
        moved_tsrs.append(replace(t, zone_start_m=a, zone_end_m=b))
    moved_targets = [
        TargetStop(t.position_m + data.draw(signs) * eps, t.target_id) for t in targets
    ]
    before = most_restrictive_profile(static, tsrs, targets, direction=direction)
    after = most_restrictive_profile(static, moved_tsrs, moved_targets, direction=direction)
    positions = inputs_positions(static, moved_tsrs, moved_targets)
    x = sample_points(*positions, *inputs_positions(static, tsrs, targets), *after.edges_m)
    v = after.at(x)
    # never above any (moved) input, at the moved boundaries and next to them
    assert_array_equal(
        np.minimum(v, brute_force(static, moved_tsrs, moved_targets, direction, x)), v
    )
    assert np.all(np.diff(after.edges_m) > 0)
    # away from every boundary that moved, nothing changed
    moved = np.array(inputs_positions(static, tsrs, targets) + positions)
    far = np.min(np.abs(x[:, None] - moved[None, :]), axis=1) > 2 * eps
    assert_array_equal(after.at(x[far]), before.at(x[far]))


@settings(max_examples=200, deadline=None)
@given(
    st.floats(0.0, 5000.0),
    st.floats(1.0, 2000.0),
    st.floats(0.0, 3000.0),
    st.floats(1.0, 30.0),
    directions,
)
def test_the_tail_obeys_the_extended_tsr(start, length, train_length, limit, direction):
    """While any part of the train is on the received stretch, the head sees v <= limit.

    Going UP the tail is at ``head - L``: some of the train is on ``[start, end]`` for heads
    in ``[start, end + L]``; going DOWN for heads in ``[start - L, end]``.
    """
    end = start + length
    applied = apply_tsr(TsrSet(1, start, end, limit, 0.0, 100.0), train_length, direction)
    static = SpeedProfile.constant(0.0, 20_000.0, INF)
    mrsp = most_restrictive_profile(static, [applied], [], direction=direction)
    if direction is UP:
        first, last = start, end + train_length
    else:
        first, last = end, start - train_length  # below km 0 the line (and speed) ends
    heads = np.linspace(first, last, 501)
    assert np.all(mrsp.at(heads) <= limit)
    # the zone ends exactly there: one train length past the exit, none on the approach
    sign = direction_sign(direction)
    for outside in (first - sign * 1e-6, last + sign * 1e-6):
        if outside > 0.0:
            assert mrsp.at(outside) == INF


def _link_extend(start, end, train_length, direction):
    config = OnboardConfig(
        train_id=7,
        ground_id=1,
        train_number="K1234",
        loco_number="SS4-0123",
        driver_id=42,
        train_length_m=train_length,
        require_auth=False,
    )
    onboard = OnboardEndpoint(config, None)
    if direction is not TravelDirection.UNKNOWN:
        onboard.update_running_info(RunningInfo(42, "K1234", "SS4-0123", direction, 10.0, start))
    applied = onboard._extend(TsrSet(3, start, end, 10.0, 0.0, 100.0))
    return applied.zone_start_m, applied.zone_end_m


@settings(max_examples=200, deadline=None)
@given(
    st.floats(0.0, 1e6),
    st.floats(0.0, 1e6),
    st.floats(0.0, 10_000.0),
    st.sampled_from(list(TravelDirection)),
)
def test_extension_agrees_with_the_link(start, end, train_length, direction):
    assume(start != end)
    assert extend_tsr(start, end, train_length, direction) == _link_extend(
        start, end, train_length, direction
    )


@settings(max_examples=200, deadline=None)
@given(
    profiles(),
    st.lists(applied_tsrs(st.integers(1, 4)), min_size=1, max_size=6).map(unique_sessions),
    st.lists(st.tuples(st.booleans(), st.integers(0, 3), st.integers(1, 5)), max_size=12),
    directions,
    st.randoms(use_true_random=False),
)
@pytest.mark.slow
def test_insert_and_cancel_by_session_are_idempotent_and_order_independent(
    static, pool, operations, direction, rnd
):
    held: dict[int, AppliedTsr] = {}
    active = ActiveTsrs()
    for is_insert, index, session in operations:
        if is_insert:
            t = pool[index % len(pool)]
            if held.get(t.session, t) != t:
                continue  # the link refuses a changed TSR under a held session
            again = active.insert(t)
            assert again.insert(t) == again  # inserting twice = once
            active = again
            held[t.session] = t
        else:
            again = active.cancel(session)
            assert again.cancel(session) == again  # cancelling twice = once
            active = again
            held.pop(session, None)
    assert dict(active) == held
    expected = most_restrictive_profile(static, list(held.values()), [], direction=direction)
    assert most_restrictive_profile(static, active, [], direction=direction) == expected
    # any order of inserts gives the same set and the same MRSP
    shuffled = list(held.values())
    rnd.shuffle(shuffled)
    reordered = ActiveTsrs()
    for t in shuffled:
        reordered = reordered.insert(t)
    assert reordered == active
    assert hash(reordered) == hash(active)
    assert most_restrictive_profile(static, shuffled, [], direction=direction) == expected
    # resent TSRs (duplicates in the input) change nothing
    assert most_restrictive_profile(static, shuffled * 2, [], direction=direction) == expected


@settings(max_examples=200, deadline=None)
@given(profiles(), profiles())
def test_minimum_is_the_pointwise_minimum_over_the_overlap(a, b):
    assume(max(a.start_m, b.start_m) < min(a.end_m, b.end_m))
    m = a.minimum(b)
    assert m == b.minimum(a)
    x = sample_points(*a.edges_m, *b.edges_m)
    assert_array_equal(m.at(x), np.minimum(a.at(x), b.at(x)))


@settings(max_examples=200, deadline=None)
@given(profiles(), tsr_lists, target_lists, directions)
@pytest.mark.slow
def test_decreases_are_every_step_down_in_travel_order(static, tsrs, targets, direction):
    mrsp = most_restrictive_profile(static, tsrs, targets, direction=direction)
    found = mrsp.decreases()
    sign = direction_sign(direction)
    s = [sign * d.position_m for d in found]
    assert s == sorted(s)
    for d in found:
        assert d.to_mps < d.from_mps
        if not probed_inside(mrsp.edges_m, d.position_m):
            continue
        left, right = beside(mrsp.edges_m, d.position_m)
        behind, ahead = (left, right) if direction is UP else (right, left)
        assert tuple(mrsp.at([behind, d.position_m])) == (d.from_mps, d.to_mps)
        assert mrsp.governor_at(ahead)[0] == d.governor
    # the same positions as the bare profile's decreases
    bare = mrsp.profile.decreases(direction)
    assert [(d.position_m, d.from_mps, d.to_mps) for d in found] == [
        (d.position_m, d.from_mps, d.to_mps) for d in bare
    ]
    # and every step down of the profile is among them
    edges, speeds = mrsp.profile.edges_m, np.concatenate(([0.0], mrsp.profile.speeds_mps, [0.0]))
    steps = speeds[1:] < speeds[:-1] if direction is UP else speeds[:-1] < speeds[1:]
    assert {d.position_m for d in found} == set(edges[steps].tolist())


# ---------------------------------------------------------------------------- hand cases


LINE = SpeedProfile([0.0, 1000.0, 2000.0, 3000.0], [20.0, 20.0, 15.0])


def test_equal_neighbours_merge_and_edges_take_the_stricter_side():
    assert_array_equal(LINE.edges_m, [0.0, 2000.0, 3000.0])
    assert_array_equal(LINE.speeds_mps, [20.0, 15.0])
    assert SpeedProfile([0, 2000, 3000], [20, 15]) == LINE
    assert hash(LINE) == hash(SpeedProfile([0, 2000, 3000], [20, 15]))
    assert_allclose(
        LINE.at([-1.0, 0.0, 500.0, 1000.0, 2000.0, 2500.0, 3000.0, 3001.0]),
        [0.0, 0.0, 20.0, 20.0, 15.0, 15.0, 0.0, 0.0],
    )
    assert LINE.restricted_stretches() == [(0.0, 2000.0, 20.0), (2000.0, 3000.0, 15.0)]


def test_unrestricted_pieces_are_not_restricted_stretches():
    p = SpeedProfile([0, 10, 20, 30], [INF, 5.0, INF])
    assert p.restricted_stretches() == [(10.0, 20.0, 5.0)]
    assert_allclose(p.at([5.0, 10.0, 15.0, 20.0, 25.0]), [INF, 5.0, 5.0, 5.0, INF])


def test_a_tsr_and_a_target_going_up():
    t = tsr(7, 1200.0, 1800.0, 10.0)
    mrsp = most_restrictive_profile(LINE, [t], [TargetStop(2800.0, 3)], direction=UP)
    assert mrsp.stretches() == [
        (0.0, 1200.0, 20.0, STATIC),
        (1200.0, 1800.0, 10.0, Governor(GovernorKind.TSR, 7)),
        (1800.0, 2000.0, 20.0, STATIC),
        (2000.0, 2800.0, 15.0, STATIC),
        (2800.0, 3000.0, 0.0, Governor(GovernorKind.TARGET, 3)),
    ]
    assert mrsp.decreases() == [
        Decrease(1200.0, 20.0, 10.0, Governor(GovernorKind.TSR, 7)),
        Decrease(2000.0, 20.0, 15.0, STATIC),
        Decrease(2800.0, 15.0, 0.0, Governor(GovernorKind.TARGET, 3)),
    ]
    assert_allclose(mrsp.at([1199.0, 1200.0, 1800.0, 1801.0, 2800.0]), [20, 10, 10, 20, 0])
    assert [str(g) for g in mrsp.governor_at([100.0, 1200.0, 2800.0, 3000.0])] == [
        "static limit",
        "TSR session 7",
        "target 3",
        "end of line",
    ]
    assert mrsp.end_of_authority == TargetStop(2800.0, 3)


def test_the_same_inputs_going_down():
    t = tsr(7, 1200.0, 1800.0, 10.0)
    targets = [TargetStop(800.0, 3), TargetStop(400.0, 4)]
    mrsp = most_restrictive_profile(LINE, [t], targets, direction=DOWN)
    assert_allclose(mrsp.profile.edges_m, [0.0, 800.0, 1200.0, 1800.0, 2000.0, 3000.0])
    assert_allclose(mrsp.profile.speeds_mps, [0.0, 20.0, 10.0, 20.0, 15.0])
    # going down 15 -> 20 at km 2 is a rise, not a decrease; the nearer target governs
    assert mrsp.decreases() == [
        Decrease(1800.0, 20.0, 10.0, Governor(GovernorKind.TSR, 7)),
        Decrease(800.0, 20.0, 0.0, Governor(GovernorKind.TARGET, 3)),
    ]
    assert [t.target_id for t in mrsp.targets] == [3, 4]


def test_the_far_end_of_the_line_is_a_decrease_to_zero():
    assert LINE.decreases(UP) == [Decrease(2000.0, 20.0, 15.0), Decrease(3000.0, 15.0, 0.0)]
    assert LINE.decreases(DOWN) == [Decrease(0.0, 20.0, 0.0)]
    mrsp = most_restrictive_profile(LINE, [], [], direction=UP)
    assert mrsp.decreases()[-1].governor == Governor(GovernorKind.LINE_END)


def test_overlapping_tsrs_the_lower_limit_governs_and_ties_name_the_lowest_session():
    tsrs = [tsr(9, 500.0, 1500.0, 8.0), tsr(4, 1000.0, 2500.0, 8.0), tsr(5, 900.0, 1100.0, 5.0)]
    mrsp = most_restrictive_profile(LINE, tsrs, [], direction=UP)
    # 1100..1500: sessions 9 and 4 both 8 m/s, the lower session is named
    assert mrsp.stretches() == [
        (0.0, 500.0, 20.0, STATIC),
        (500.0, 900.0, 8.0, Governor(GovernorKind.TSR, 9)),
        (900.0, 1100.0, 5.0, Governor(GovernorKind.TSR, 5)),
        (1100.0, 2500.0, 8.0, Governor(GovernorKind.TSR, 4)),
        (2500.0, 3000.0, 15.0, STATIC),
    ]
    # the speed alone merges 500..900 with nothing: 8 | 5 | 8
    assert_allclose(mrsp.profile.edges_m, [0.0, 500.0, 900.0, 1100.0, 2500.0, 3000.0])


def test_a_tsr_equal_to_the_static_limit_is_named_static():
    mrsp = most_restrictive_profile(LINE, [tsr(2, 2200.0, 2400.0, 15.0)], [], direction=UP)
    assert mrsp.stretches()[-1] == (2000.0, 3000.0, 15.0, STATIC)


def test_a_tsr_reaching_beyond_the_line_is_clipped_to_it():
    mrsp = most_restrictive_profile(LINE, [tsr(2, 2500.0, 9000.0, 4.0)], [], direction=UP)
    assert_allclose(mrsp.profile.edges_m, [0.0, 2000.0, 2500.0, 3000.0])
    assert_allclose(mrsp.profile.speeds_mps, [20.0, 15.0, 4.0])


def test_a_tsr_out_of_its_validity_window_is_ignored_when_now_is_given():
    t = tsr(2, 500.0, 700.0, 5.0, valid_from_s=100.0, valid_until_s=200.0)
    assert [tsr_in_force(t, now) for now in (99.9, 100.0, 199.9, 200.0)] == [
        False,
        True,
        True,
        False,
    ]
    for now, expected in ((50.0, 20.0), (150.0, 5.0), (200.0, 20.0), (None, 5.0)):
        mrsp = most_restrictive_profile(LINE, [t], [], direction=UP, now_s=now)
        assert mrsp.at(600.0) == expected


def test_extension_by_hand():
    assert extend_tsr(1000.0, 2000.0, 300.0, UP) == (1000.0, 2300.0)
    assert extend_tsr(2000.0, 1000.0, 300.0, UP) == (1000.0, 2300.0)  # either order
    assert extend_tsr(1000.0, 2000.0, 300.0, DOWN) == (700.0, 2000.0)
    assert extend_tsr(100.0, 2000.0, 300.0, DOWN) == (0.0, 2000.0)  # not below km 0
    assert extend_tsr(1000.0, 2000.0, 300.0, TravelDirection.UNKNOWN) == (700.0, 2300.0)
    assert extend_tsr(1000.0, 2000.0, 300.0, UP) == _link_extend(1000.0, 2000.0, 300.0, UP)


def test_apply_tsr_records_the_received_stretch_and_the_zone():
    applied = apply_tsr(TsrSet(11, 1000.0, 2000.0, 12.5, 10.0, 20.0), 300.0, DOWN)
    assert applied == AppliedTsr(11, 1000.0, 2000.0, 700.0, 2000.0, 12.5, 10.0, 20.0)


def test_target_stop_from_a_red_signal_is_on_the_approach_side():
    signal = TargetPoint(5, 4000.0, TargetReason.TRAIN_AHEAD)
    assert TargetStop.from_target_point(signal, 250.0, UP) == TargetStop(3750.0, 5)
    assert TargetStop.from_target_point(signal, 250.0, DOWN) == TargetStop(4250.0, 5)


def test_coordinate_conversion_round_trips():
    x = np.array([1000.0, 1500.0, 250.0])
    assert_allclose(travelled_m(x, UP, 1000.0), [0.0, 500.0, -750.0])
    assert_allclose(travelled_m(x, DOWN, 1000.0), [0.0, -500.0, 750.0])
    for direction in (UP, DOWN):
        assert_allclose(km_post_m(travelled_m(x, direction, 42.0), direction, 42.0), x)
    assert (direction_sign(UP), direction_sign(DOWN)) == (1.0, -1.0)


def test_active_tsrs_insert_cancel_by_hand():
    a, b = tsr(1, 0.0, 10.0, 5.0), tsr(2, 20.0, 30.0, 5.0)
    s = ActiveTsrs().insert(a).insert(b).insert(a)
    assert list(s) == [1, 2] and s[1] == a
    assert s.cancel(1).cancel(1) == ActiveTsrs([b])
    assert s.cancel(99) == s
    assert s.in_force(1e9) == ActiveTsrs()


def test_mrsp_equality_is_structural():
    a = most_restrictive_profile(LINE, [tsr(1, 10.0, 20.0, 3.0)], [], direction=UP)
    b = most_restrictive_profile(LINE, ActiveTsrs([tsr(1, 10.0, 20.0, 3.0)]), [], direction=UP)
    assert a == b and hash(a) == hash(b)
    assert a != most_restrictive_profile(LINE, [tsr(1, 10.0, 20.0, 3.0)], [], direction=DOWN)
    assert isinstance(a, Mrsp)
    with pytest.raises(AttributeError):
        a.direction = DOWN  # type: ignore[misc]
    with pytest.raises(ValueError):
        LINE.edges_m[0] = 5.0


# ---------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    ("edges", "speeds", "field", "value"),
    [
        ([0.0, 20.0, 10.0], [1.0, 2.0], "edges_m[2]", 10.0),
        ([0.0, 10.0, 10.0], [1.0, 2.0], "edges_m[2]", 10.0),
        ([0.0, math.nan], [1.0], "edges_m[1]", None),
        ([0.0, INF], [1.0], "edges_m[1]", INF),
        ([0.0], [], "edges_m", None),
        ([0.0, 10.0], [-1.0], "speeds_mps[0]", -1.0),
        ([0.0, 10.0, 20.0], [1.0, math.nan], "speeds_mps[1]", None),
        ([0.0, 10.0], [1.0, 2.0], "speeds_mps", None),
    ],
)
def test_bad_profiles_name_the_field_the_value_and_what_is_allowed(edges, speeds, field, value):
    with pytest.raises(ConfigError) as err:
        SpeedProfile(edges, speeds)
    assert err.value.field == field
    if value is not None:
        assert err.value.value == value
    assert err.value.allowed
    assert field in str(err.value) and "expected" in str(err.value)


@pytest.mark.parametrize(
    ("bad", "field"),
    [
        (tsr(3, 500.0, 500.0, 5.0), "tsrs[session 3].zone_end_m"),
        (tsr(3, 600.0, 500.0, 5.0), "tsrs[session 3].zone_end_m"),
        (tsr(3, math.nan, 500.0, 5.0), "tsrs[session 3].zone_start_m"),
        (tsr(3, 100.0, 500.0, -1.0), "tsrs[session 3].limit_mps"),
        (tsr(3, 100.0, 500.0, math.nan), "tsrs[session 3].limit_mps"),
    ],
)
def test_bad_tsrs_are_refused(bad, field):
    with pytest.raises(ConfigError) as err:
        most_restrictive_profile(LINE, [bad], [], direction=UP)
    assert err.value.field == field


def test_two_restrictions_under_one_session_are_refused():
    with pytest.raises(ConfigError, match="session 3"):
        ActiveTsrs([tsr(3, 0.0, 10.0, 5.0)]).insert(tsr(3, 0.0, 10.0, 6.0))


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: extend_tsr(10.0, 10.0, 100.0, UP), "tsr.end_m"),
        (lambda: extend_tsr(math.nan, 10.0, 100.0, UP), "tsr.start_m"),
        (lambda: extend_tsr(0.0, 10.0, -1.0, UP), "train_length_m"),
        (lambda: TargetStop(math.nan, 1), "target.position_m"),
        (lambda: TargetStop(10.0, -1), "target.target_id"),
        (lambda: LINE.at([1.0, math.nan]), "position_m"),
        (lambda: LINE.minimum(SpeedProfile([3000.0, 4000.0], [1.0])), "other"),
        (
            lambda: most_restrictive_profile(LINE, [], [], direction=TravelDirection.UNKNOWN),
            "direction",
        ),
        (lambda: most_restrictive_profile(LINE, [], [], direction=UP, now_s=math.nan), "now_s"),
    ],
)
def test_other_bad_inputs(call, field):
    with pytest.raises(ConfigError) as err:
        call()
    assert err.value.field == field


# ---------------------------------------------------------------- the lowest along a stretch

#: 80 up to km 1, 60 on km 1-2, 100 to km 3, 40 on km 3-3.1, 100 to km 5 [m/s for short]
ALONG = SpeedProfile([0.0, 1000.0, 2000.0, 3000.0, 3100.0, 5000.0], [80, 60, 100, 40, 100])


@pytest.mark.parametrize(
    ("low", "high", "lowest"),
    [
        (100.0, 900.0, 80.0),  # inside one piece
        (500.0, 1000.0, 60.0),  # touching an edge: the stricter side
        (2000.0, 2500.0, 60.0),  # the tail still on the edge of the lower limit
        (2000.001, 2500.0, 100.0),  # and just off it
        (2500.0, 3500.0, 40.0),  # a short slow stretch under the middle
        (1500.0, 1500.0, 60.0),  # a point
        (-400.0, 200.0, 80.0),  # beyond the start: held to the end piece, not to 0
        (4800.0, 5600.0, 100.0),  # beyond the end
    ],
)
def test_the_lowest_along_a_stretch_by_hand(low: float, high: float, lowest: float) -> None:
    assert ALONG.lowest_along(low, high) == lowest


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-500.0, 5500.0, allow_nan=False),
    st.floats(0.0, 3000.0, allow_nan=False),
)
def test_the_lowest_along_a_stretch_is_the_least_of_the_speeds_on_it(
    low: float, length: float
) -> None:
    high = low + length
    a, b = np.clip([low, high], ALONG.start_m, ALONG.end_m)
    # what at() says on the clipped stretch: at both ends, every edge between and each
    # piece's midpoint between (at() is 0 at the profile's own end points: kept inside)
    edges = ALONG.edges_m[(ALONG.edges_m >= a) & (ALONG.edges_m <= b)]
    points = np.unique(np.concatenate(([a, b], edges)))
    inside = np.concatenate((points, (points[:-1] + points[1:]) / 2.0))
    inside = inside[(inside > ALONG.start_m) & (inside < ALONG.end_m)]
    ends = ALONG.speeds_mps[[0, -1]][[a <= ALONG.start_m, b >= ALONG.end_m]]
    expected = min(np.min(ALONG.at(inside), initial=np.inf), np.min(ends, initial=np.inf))
    assert ALONG.lowest_along(low, high) == expected


def test_the_lowest_along_keeps_the_shape_of_what_it_is_given() -> None:
    lows = np.array([[100.0, 2500.0], [1500.0, 4800.0]])
    assert_array_equal(ALONG.lowest_along(lows, lows + 600.0), [[80.0, 40.0], [60.0, 100.0]])
    assert ALONG.lowest_along(np.empty(0), np.empty(0)).shape == (0,)
    with pytest.raises(ConfigError, match="position_m"):
        ALONG.lowest_along([math.nan], [1.0])
