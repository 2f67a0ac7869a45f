"""The names of the receive-side safety checks (shared by errors and events)."""

from __future__ import annotations

from enum import StrEnum


class Check(StrEnum):
    """The receive-side checks, in the order a frame meets them."""

    FRAMING = "framing"  # header byte / stuffing / truncated frame
    VERSION = "version"  # version byte and reserved flag bits
    LENGTH = "length"  # length field, body length for the type
    CRC = "crc"  # CRC-32 over the unstuffed frame
    TYPE = "type"  # known message type, allowed in this direction
    SOURCE = "source"  # source device id
    DESTINATION = "destination"  # destination device id
    AUTH = "auth"  # key id known, HMAC-SHA256 tag correct, auth required
    BODY = "body"  # every field in its documented range
    SEQUENCE = "sequence"  # repeated or out-of-order sequence number
    TIMESTAMP = "timestamp"  # not newer than the last accepted of this message type
    DELAY = "delay"  # echoed timestamp older than the round-trip bound
    STATE = "state"  # message not allowed in the endpoint's current state
