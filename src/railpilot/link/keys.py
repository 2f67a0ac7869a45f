"""Per-train HMAC keys: an in-memory key store and a loader for a key file.

Each train has its own keys (shared by that train's onboard unit and the ground), each
under a key id (1..65535). The *active* key id is the one used to send; every key present
is accepted on receipt. That is how keys rotate without dropping the link: install the
new key on both ends, switch the active id on each end (in any order), then remove the
old key.

Key file (TOML), readable by its owner only (``chmod 600``)::

    [[train]]
    id = 1001                   # train (onboard device) id
    active_key = 2
    [train.keys]
    1 = "00112233445566778899aabbccddeeff"    # hex, 16..64 bytes
    2 = "ffeeddccbbaa99887766554433221100"

No method, repr or error message of this module ever shows key bytes.
"""

from __future__ import annotations

import hashlib
import os
import stat
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from railpilot.errors import shown
from railpilot.schema.keys import MAX_KEY_BYTES, MAX_KEY_ID, MAX_TRAIN_ID, MIN_KEY_BYTES, KeyFile
from railpilot.textfile import TOO_MANY_DIGITS

from .errors import KeyFileError, LinkConfigError


class KeyStore:
    """train id -> {key id -> key bytes}, plus the active key id per train."""

    def __init__(self) -> None:
        self._keys: dict[int, dict[int, bytes]] = {}
        self._active: dict[int, int] = {}

    def __repr__(self) -> str:  # never show key material
        trains = {t: sorted(k) for t, k in self._keys.items()}
        return f"KeyStore(key ids per train={trains}, active={self._active})"

    def add_key(self, train_id: int, key_id: int, key: bytes, *, activate: bool = False) -> None:
        """Install ``key`` for ``train_id`` under ``key_id``; the first key becomes active."""
        if type(train_id) is not int or not 1 <= train_id <= MAX_TRAIN_ID:
            raise LinkConfigError("train_id", train_id, f"an integer in [1, {MAX_TRAIN_ID}]")
        if type(key_id) is not int or not 1 <= key_id <= MAX_KEY_ID:
            raise LinkConfigError("key_id", key_id, f"an integer in [1, {MAX_KEY_ID}]")
        if not isinstance(key, bytes) or not MIN_KEY_BYTES <= len(key) <= MAX_KEY_BYTES:
            # Report only the length, never the key.
            length = len(key) if isinstance(key, bytes) else type(key).__name__
            raise LinkConfigError(
                f"key[{train_id}][{key_id}] length",
                length,
                f"{MIN_KEY_BYTES}..{MAX_KEY_BYTES} bytes",
            )
        self._keys.setdefault(train_id, {})[key_id] = key
        if activate or train_id not in self._active:
            self._active[train_id] = key_id

    def remove_key(self, train_id: int, key_id: int) -> None:
        """Retire a key; frames under it are then rejected. The active key cannot go."""
        if self._active.get(train_id) == key_id:
            raise LinkConfigError(
                f"key[{train_id}]", key_id, "a key id that is not the active one (rotate first)"
            )
        self._keys.get(train_id, {}).pop(key_id, None)

    def set_active(self, train_id: int, key_id: int) -> None:
        """Send with ``key_id`` from now on (the key must be installed)."""
        if key_id not in self._keys.get(train_id, {}):
            raise LinkConfigError(f"active key of train {train_id}", key_id, "an installed key id")
        self._active[train_id] = key_id

    def lookup(self, train_id: int, key_id: int) -> bytes | None:
        """The key for verifying a frame, or ``None`` if unknown."""
        keys = self._keys.get(train_id)
        return None if keys is None else keys.get(key_id)

    def active(self, train_id: int) -> tuple[int, bytes] | None:
        """``(key id, key)`` to send with, or ``None`` when the train has no key."""
        key_id = self._active.get(train_id)
        if key_id is None:
            return None
        return key_id, self._keys[train_id][key_id]

    def trains(self) -> frozenset[int]:
        return frozenset(self._keys)

    def key_ids(self, train_id: int) -> frozenset[int]:
        return frozenset(self._keys.get(train_id, {}))


def parse_key_table(document: Mapping[str, Any], source: str = "<key table>") -> KeyStore:
    """Build a :class:`KeyStore` from a parsed key file (see the module docstring; the
    format: railpilot.schema.keys)."""
    try:
        table = KeyFile.model_validate(document)
    except ValidationError as exc:
        raise KeyFileError(_fault(exc.errors(include_url=False)[0], source)) from None
    store = KeyStore()
    for index, entry in enumerate(table.train):
        where = f"{source}: train[{index}]"
        for key_id_text, hex_key in entry.keys.items():
            try:
                key_id = int(key_id_text)
                key = bytes.fromhex(hex_key)
            except ValueError:
                raise KeyFileError(
                    f"{where}: key {key_id_text!r} needs an integer id and a hex string value"
                ) from None
            try:
                store.add_key(entry.id, key_id, key)
            except LinkConfigError as exc:
                # the key store's own name for it, said as the file writes it
                field = "id" if exc.field == "train_id" else exc.field
                raise KeyFileError(
                    f"{where}.{field} = {shown(exc.value)} is not allowed: expected {exc.allowed}"
                ) from None
        active = entry.active_key if entry.given("active_key") else min(map(int, entry.keys))
        try:
            store.set_active(entry.id, active)
        except LinkConfigError:
            raise KeyFileError(
                f"{where}: active_key {shown(active)} is not one of its key ids"
            ) from None
    return store


def _fault(fault: Any, source: str) -> str:
    """A key file's first fault, as its error says it: the entry and the key, and the
    value only where it cannot be a key (:func:`_shown`)."""
    loc = fault["loc"]
    if len(loc) < 2:  # no [[train]] list, or an empty one
        return f"{source}: expected at least one [[train]] table"
    where = f"{source}: train[{loc[1]}]"
    value = None if fault["type"] == "missing" else fault["input"]
    if len(loc) == 2:
        return f"{where}: expected a table"
    if loc[2] == "id":
        return f"{where}: id must be an integer train id, got {_shown(value)}"
    if loc[2] == "active_key":  # not a bool, a float (inf, 1.0) or a string
        return f"{where}: active_key must be an integer key id, got {_shown(value)}"
    if len(loc) == 3:
        return f"{where}: expected a non-empty [train.keys] table"
    key_id_text = loc[3]
    try:
        int(key_id_text)
    except ValueError:
        return f"{where}: key {key_id_text!r} needs an integer id and a hex string value"
    return f"{where}: key {key_id_text!r} must be a hex string"


def _shown(value: object) -> str:
    """A key-file value for an error message: numbers and booleans as written, anything
    else only by its type (a string there may be a key pasted in the wrong place)."""
    if value is None:
        return "nothing (the entry is missing)"
    if isinstance(value, bool | int | float):
        return repr(value).lower() if isinstance(value, bool) else shown(value)
    return f"a {type(value).__name__}"


def load_key_file(path: str | os.PathLike[str]) -> KeyStore:
    """Read a key file, refusing one that group or others may read or write.

    Raises :class:`KeyFileError` (and loads nothing) when the file is missing, has mode
    bits in ``0o077`` set, or is malformed.
    """
    file = Path(path)
    try:
        mode = file.stat().st_mode
    except OSError as exc:
        raise KeyFileError(f"cannot read key file {file}: {exc.strerror}") from None
    if os.name == "posix" and mode & 0o077:
        raise KeyFileError(
            f"key file {file} has mode {stat.S_IMODE(mode):#o}, open to group/others; "
            f"run `chmod 600 {file}`"
        )
    try:
        document = tomllib.loads(file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise KeyFileError(f"cannot read key file {file}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        # The TOML error quotes a position, not the content, so it cannot leak a key.
        raise KeyFileError(f"key file {file} is not valid TOML ({exc})") from None
    except ValueError:  # tomllib's int() of a literal past Python's digit limit
        raise KeyFileError(f"key file {file} is not valid TOML ({TOO_MANY_DIGITS})") from None
    return parse_key_table(document, str(file))


def seeded_test_keys(seed: int, train_ids: Iterable[int]) -> KeyStore:
    """Per-train keys derived from ``seed``, for runs that must authenticate but have no key
    file: the co-simulation's line runs, the load test, tests and benchmarks.

    Anyone who knows the seed knows the keys: they are test keys, kept in memory, never
    written and never for service. The same seed and ids give the same keys (key id 1), so
    a seeded run is repeated to the bit.
    """
    keys = KeyStore()
    for train in train_ids:
        keys.add_key(
            train, 1, hashlib.sha256(f"railpilot-loadtest:{seed}:{train}".encode()).digest()
        )
    return keys
