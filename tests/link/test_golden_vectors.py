"""The golden vectors of docs/protocol.md, read straight from the document.

Each ```golden-vector block is decoded and every documented field checked; then the
documented fields are encoded and must give the documented bytes. A change to the wire
format that forgets the specification fails here.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from railpilot.link import (
    FrameDecoder,
    KeyStore,
    decode_body,
    decode_stream,
    encode_body,
    encode_frame,
    parse_frame,
    verify_mac,
)
from railpilot.link import messages as catalogue
from railpilot.link.messages import MESSAGE_CLASSES

from .helpers import GROUND_ID

SPEC = Path(__file__).resolve().parents[2] / "docs" / "protocol.md"
BLOCK = re.compile(r"```golden-vector\n(.*?)```", re.S)


def load_vectors() -> list[dict[str, str]]:
    vectors = []
    for block in BLOCK.findall(SPEC.read_text(encoding="utf-8")):
        entries = {}
        for line in block.strip().splitlines():
            key, _, value = line.partition(":")
            entries[key.strip()] = value.strip()
        vectors.append(entries)
    return vectors


VECTORS = load_vectors()


def field_value(text: str) -> object:
    enum_ref = re.fullmatch(r"([A-Za-z]+)\.([A-Z_]+)", text)
    if enum_ref:
        return getattr(getattr(catalogue, enum_ref.group(1)), enum_ref.group(2))
    return ast.literal_eval(text)


def expected_message(vector: dict[str, str]) -> catalogue.Message:
    cls = next(c for c in MESSAGE_CLASSES.values() if c.__name__ == vector["message"])
    fields = {
        k[len("field.") :]: field_value(v) for k, v in vector.items() if k.startswith("field.")
    }
    return cls(**fields)


def hex_or_none(text: str) -> bytes | None:
    return None if text == "-" else bytes.fromhex(text)


def test_spec_has_plain_authenticated_and_stuffed_vectors() -> None:
    assert len(VECTORS) >= 3
    assert any(v["key"] == "-" for v in VECTORS)
    assert any(v["key"] != "-" for v in VECTORS)
    assert any("7e7e" in v["wire"] for v in VECTORS)


@pytest.mark.parametrize("vector", VECTORS, ids=[v["name"] for v in VECTORS])
def test_vector_decodes_to_the_documented_fields(vector: dict[str, str]) -> None:
    wire = bytes.fromhex(vector["wire"])
    [raw] = FrameDecoder().feed(wire)
    assert raw == bytes.fromhex(vector["unstuffed"])
    assert isinstance(raw, bytes)
    frame = parse_frame(raw)
    assert frame.message_type == int(vector["message_type"], 16)
    assert frame.source_id == int(vector["source_id"])
    assert frame.destination_id == int(vector["destination_id"])
    assert frame.sequence == int(vector["sequence"])
    assert frame.timestamp_us == int(vector["timestamp_us"])
    assert frame.echo_timestamp_us == int(vector["echo_timestamp_us"])
    assert frame.key_id == int(vector["key_id"])
    assert frame.body == (hex_or_none(vector["body"]) or b"")
    assert frame.mac == hex_or_none(vector["mac"])
    assert frame.crc == int(vector["crc"], 16)
    assert decode_body(frame.message_type, frame.body) == expected_message(vector)
    key = hex_or_none(vector["key"])
    if key is not None:
        verify_mac(key, raw, frame)


@pytest.mark.parametrize("vector", VECTORS, ids=[v["name"] for v in VECTORS])
def test_documented_fields_encode_to_the_vector_bytes(vector: dict[str, str]) -> None:
    message = expected_message(vector)
    assert encode_body(message) == (hex_or_none(vector["body"]) or b"")
    key = hex_or_none(vector["key"])
    wire = encode_frame(
        int(vector["message_type"], 16),
        int(vector["source_id"]),
        int(vector["destination_id"]),
        int(vector["sequence"]),
        int(vector["timestamp_us"]),
        int(vector["echo_timestamp_us"]),
        encode_body(message),
        int(vector["key_id"]),
        key,
    )
    assert wire.hex() == vector["wire"]


@pytest.mark.parametrize("vector", VECTORS, ids=[v["name"] for v in VECTORS])
def test_decode_tool_passes_every_stateless_check_of_the_vector(vector: dict[str, str]) -> None:
    keys = KeyStore()
    key = hex_or_none(vector["key"])
    if key is not None:
        # The train is whichever end is not the ground.
        src, dst = int(vector["source_id"]), int(vector["destination_id"])
        train = dst if src == GROUND_ID else src
        keys.add_key(train, int(vector["key_id"]), key)
    [report] = decode_stream(bytes.fromhex(vector["wire"]), keys)
    assert report.ok
    assert report.message == expected_message(vector)
