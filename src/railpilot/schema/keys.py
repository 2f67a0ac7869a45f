"""The key file's format (per-train HMAC keys, docs/protocol.md): a ``[[train]]`` table
per train, its keys by key id in hex, and the key id it sends with.

These models check each key's type; the values' ranges (a train id, a key id, a key's
length in bytes, an active key among the train's keys) are the key store's to check,
railpilot.link.keys, whose errors never quote a key. Keys these tables do not know are
ignored.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import ConfigDict, Field

from railpilot.schema.fields import NOT_GIVEN, FileTable

#: a key's length [bytes], the largest key id (0 marks an unauthenticated frame) and the
#: largest train id
MIN_KEY_BYTES = 16
MAX_KEY_BYTES = 64
MAX_KEY_ID = 0xFFFF
MAX_TRAIN_ID = 0xFFFF_FFFF


class KeyTable(FileTable):
    # a key file's other keys are the owner's notes: they are not refused
    model_config = ConfigDict(extra="ignore")


class TrainKeysTable(KeyTable):
    """``[[train]]``: one train's keys; every key present is accepted on receipt, the
    active one is used to send."""

    id: Annotated[int, Field(json_schema_extra={"minimum": 1, "maximum": MAX_TRAIN_ID})]
    #: ``[train.keys]``: key id (1..65535) -> the key in hex (16..64 bytes)
    keys: Annotated[
        dict[str, str],
        Field(
            min_length=1,
            json_schema_extra={
                "additionalProperties": {
                    "type": "string",
                    # pairs of hex digits, spaces between them allowed (bytes.fromhex)
                    "pattern": "^\\s*([0-9a-fA-F]{2}\\s*)+$",
                },
            },
        ),
    ]
    #: the key id to send with (default: the lowest)
    active_key: Annotated[int, Field(json_schema_extra={"minimum": 1, "maximum": MAX_KEY_ID})] = (
        NOT_GIVEN
    )


class KeyFile(KeyTable):
    """A key file: per-train HMAC keys, readable by its owner only (``chmod 600``)."""

    train: Annotated[list[TrainKeysTable], Field(min_length=1)]
