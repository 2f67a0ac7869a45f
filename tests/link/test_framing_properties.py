"""Property tests: stuffing and whole-frame round trips through arbitrary segmentation."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from railpilot.link import (
    FrameDecoder,
    Message,
    decode_body,
    encode_body,
    encode_frame,
    parse_frame,
    stuff,
    unstuff,
    verify_mac,
)

from .test_messages import any_message

header_fields = st.fixed_dictionaries(
    {
        "source_id": st.integers(1, 0xFFFF_FFFF),
        "destination_id": st.integers(1, 0xFFFF_FFFF),
        "sequence": st.integers(0, 0xFFFF_FFFF),
        "timestamp_us": st.integers(0, 2**64 - 1),
        "echo_timestamp_us": st.integers(0, 2**64 - 1),
    }
)
keys = st.one_of(st.none(), st.binary(min_size=16, max_size=64))


@given(st.binary(max_size=300))
def test_unstuffing_inverts_stuffing(data: bytes) -> None:
    assert unstuff(stuff(data)[1:]) == data


@given(st.binary(max_size=300))
def test_stuffed_frame_has_no_lone_header_byte(data: bytes) -> None:
    stuffed = stuff(b"\x01" + data)[1:]
    # Read left to right as the decoder does, every 0x7E is half of a pair.
    assert b"\x7e" not in stuffed.replace(b"\x7e\x7e", b"")
    assert len(stuffed) == 1 + len(data) + data.count(b"\x7e")


@settings(max_examples=200, deadline=None)
@given(any_message, header_fields, keys)
def test_frame_round_trip_for_every_message_type(
    message: Message, fields: dict[str, int], key: bytes | None
) -> None:
    wire = encode_frame(
        message.TYPE, body=encode_body(message), key_id=1 if key else 0, key=key, **fields
    )
    [raw] = FrameDecoder().feed(wire)
    assert isinstance(raw, bytes)
    frame = parse_frame(raw)
    assert {k: getattr(frame, k) for k in fields} == fields
    assert decode_body(frame.message_type, frame.body) == message
    if key is not None:
        verify_mac(key, raw, frame)


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.tuples(any_message, header_fields, keys), min_size=1, max_size=6),
    st.lists(st.integers(1, 60), min_size=1, max_size=50),
    st.binary(max_size=20).filter(lambda g: b"\x7e" not in g),
)
def test_any_segmentation_of_a_frame_stream_yields_the_same_frames(
    items: list[tuple[Message, dict[str, int], bytes | None]],
    cuts: list[int],
    garbage: bytes,
) -> None:
    wires = [
        encode_frame(m.TYPE, body=encode_body(m), key_id=1 if k else 0, key=k, **f)
        for m, f, k in items
    ]
    stream = garbage + b"".join(wires) + garbage
    decoder = FrameDecoder()
    out: list[object] = []
    i = 0
    for n in cuts * (len(stream) // max(1, sum(cuts)) + 1):
        if i >= len(stream):
            break
        out += decoder.feed(stream[i : i + n])
        i += n
    out += decoder.feed(stream[i:])
    assert out == [unstuff(w[1:]) for w in wires]
