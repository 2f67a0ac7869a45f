"""Streaming decoder: stuffing, partial frames, garbage, resynchronisation, bounds."""

from __future__ import annotations

import pytest

from railpilot.link import FrameDecoder, FramingError, LengthError, VersionError, stuff, unstuff
from railpilot.link.codec import encode_body
from railpilot.link.frame import encode_frame
from railpilot.link.framing import HEADER_BYTE, MIN_FRAME_LENGTH
from railpilot.link.messages import DispatchCommand, Heartbeat, MessageType, TsrSetAck, TsrSetResult

from .helpers import GROUND_ID, TRAIN_ID


def wire_frame(sequence: int = 0, body_message: object = None) -> bytes:
    message = body_message if body_message is not None else Heartbeat()
    return encode_frame(
        message.TYPE,  # type: ignore[attr-defined]
        TRAIN_ID,
        GROUND_ID,
        sequence,
        1_700_000_000_000_000 + sequence,
        0,
        encode_body(message),  # type: ignore[arg-type]
    )


def frames_only(items: list[bytes | Exception]) -> list[bytes]:
    return [i for i in items if isinstance(i, bytes)]


def test_stuffing_doubles_every_header_byte_and_nothing_else() -> None:
    assert stuff(b"\x01\x7e\x02\x7e\x7e") == b"\x7e\x01\x7e\x7e\x02\x7e\x7e\x7e\x7e"


def test_unstuff_inverts_stuff() -> None:
    data = bytes(range(256)) * 2
    assert unstuff(stuff(data)[1:]) == data


def test_one_frame_in_one_read_decodes() -> None:
    wire = wire_frame()
    assert FrameDecoder().feed(wire) == [unstuff(wire[1:])]


def test_frame_fed_byte_by_byte_decodes_once_complete() -> None:
    wire = wire_frame(body_message=TsrSetAck(126, TsrSetResult.APPLIED))  # contains 7e 7e
    decoder = FrameDecoder()
    outputs = [decoder.feed(wire[i : i + 1]) for i in range(len(wire))]
    assert all(o == [] for o in outputs[:-1])
    assert outputs[-1] == [unstuff(wire[1:])]


def test_several_frames_in_one_read_all_decode_in_order() -> None:
    wires = [wire_frame(seq) for seq in range(5)]
    assert FrameDecoder().feed(b"".join(wires)) == [unstuff(w[1:]) for w in wires]


def test_garbage_before_and_after_is_discarded_and_counted() -> None:
    decoder = FrameDecoder()
    wire = wire_frame()
    items = decoder.feed(b"\x00\x11garbage" + wire + b"\x22tail")
    assert items == [unstuff(wire[1:])]
    assert decoder.bytes_discarded == len(b"\x00\x11garbage") + len(b"\x22tail")


def test_stuffed_pairs_in_garbage_are_not_taken_for_a_header() -> None:
    wire = wire_frame()
    decoder = FrameDecoder()
    assert decoder.feed(b"\x7e\x7e\x7e\x7e\x55" + wire) == [unstuff(wire[1:])]


def test_header_byte_inside_frame_reports_truncation_and_resyncs() -> None:
    first, second = wire_frame(0), wire_frame(1)
    items = FrameDecoder().feed(first[:20] + second)
    assert isinstance(items[0], FramingError)
    assert items[1:] == [unstuff(second[1:])]


def test_wrong_version_is_rejected_and_next_frame_still_decodes() -> None:
    bad = bytearray(wire_frame(0))
    bad[1] = 0x02
    good = wire_frame(1)
    items = FrameDecoder().feed(bytes(bad) + good)
    assert isinstance(items[0], VersionError)
    assert frames_only(items) == [unstuff(good[1:])]


def test_length_above_maximum_is_rejected_without_waiting_for_the_bytes() -> None:
    decoder = FrameDecoder(max_frame_length=100)
    long_frame = wire_frame(body_message=DispatchCommand(1, "x" * 200))
    items = decoder.feed(long_frame[:10])
    assert len(items) == 1 and isinstance(items[0], LengthError)


def test_length_below_minimum_is_rejected() -> None:
    bad = bytearray(wire_frame())
    bad[3:5] = (MIN_FRAME_LENGTH - 1).to_bytes(2, "big")
    items = FrameDecoder().feed(bytes(bad))
    assert isinstance(items[0], LengthError)


def test_buffer_never_exceeds_one_maximally_stuffed_frame() -> None:
    decoder = FrameDecoder(max_frame_length=100)
    # A header and a legal length, then a flood of stuffed pairs that never completes.
    start = b"\x7e\x01\x00\x00\x64"
    peak = 0
    for _ in range(2000):
        decoder.feed(start if decoder.buffered_bytes == 0 else b"\x7e\x7e" * 7)
        peak = max(peak, decoder.buffered_bytes)
    assert peak <= decoder.max_buffered_bytes


def test_huge_garbage_read_leaves_the_buffer_bounded() -> None:
    decoder = FrameDecoder()
    decoder.feed(bytes(range(HEADER_BYTE)) * 20_000)
    assert decoder.buffered_bytes <= decoder.max_buffered_bytes


def test_lone_header_byte_at_end_of_read_waits_for_the_next_byte() -> None:
    decoder = FrameDecoder()
    wire = wire_frame()
    assert decoder.feed(b"junk\x7e") == []
    assert decoder.feed(wire[1:]) == [unstuff(wire[1:])]


def test_max_frame_length_out_of_range_is_refused() -> None:
    with pytest.raises(ValueError, match="max_frame_length"):
        FrameDecoder(max_frame_length=10)


def test_every_message_type_code_fits_the_header() -> None:
    # The byte after the header byte is the version, never 0x7E: frame starts stay
    # unambiguous (docs/protocol.md section 3).
    assert all(t != HEADER_BYTE for t in MessageType)
    assert wire_frame()[1] == 0x01


def test_pending_frame_reports_what_came_of_a_frame_cut_by_the_end_of_input() -> None:
    wire = wire_frame()  # 39 bytes, no stuffing
    decoder = FrameDecoder()
    assert decoder.feed(wire[:20]) == []
    assert decoder.pending_frame() == (19, 39)  # header byte not counted
    assert decoder.feed(wire[20:]) == [wire[1:]]  # read-only: the frame still completes
    assert decoder.pending_frame() is None


def test_pending_frame_before_the_length_field_has_no_length() -> None:
    decoder = FrameDecoder()
    decoder.feed(wire_frame()[:3])
    assert decoder.pending_frame() == (2, None)
    decoder.reset()
    decoder.feed(b"garbage" + bytes([HEADER_BYTE]))
    assert decoder.pending_frame() == (0, None)  # a lone header byte at the very end


def test_pending_frame_counts_stuffed_pairs_once_and_not_a_dangling_half() -> None:
    # A frame whose sequence is 0x7E: frame byte 22 is stuffed on the wire.
    wire = wire_frame(sequence=0x7E)
    pair = wire.index(b"\x7e\x7e")
    decoder = FrameDecoder()
    decoder.feed(wire[: pair + 1])  # ends between the two halves of the pair
    assert decoder.pending_frame() == (pair - 1, 39)
    decoder.reset()
    decoder.feed(wire[: pair + 2])
    assert decoder.pending_frame() == (pair, 39)


def test_no_pending_frame_after_garbage_or_complete_frames() -> None:
    decoder = FrameDecoder()
    assert decoder.pending_frame() is None
    decoder.feed(b"\x00\x7e\x7e\x01" + wire_frame())
    assert decoder.pending_frame() is None
