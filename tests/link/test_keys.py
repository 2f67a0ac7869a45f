"""Key store and key file loader: permissions, format, and no key material in messages."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from railpilot.link import KeyFileError, KeyStore, LinkConfigError, load_key_file

from .helpers import KEY_1, KEY_2, KEY_FILE


def write_key_file(tmp_path: Path, text: str, mode: int = 0o600) -> Path:
    path = tmp_path / "keys.toml"
    path.write_text(text, encoding="utf-8")
    os.chmod(path, mode)
    return path


def test_owner_only_key_file_loads_keys_and_active_ids(tmp_path: Path) -> None:
    store = load_key_file(write_key_file(tmp_path, KEY_FILE))
    assert store.active(1001) == (2, KEY_2)
    assert store.lookup(1001, 1) == KEY_1
    assert store.active(2002) == (7, KEY_2)  # the only key is active by default


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o660, 0o644, 0o601])
def test_key_file_open_to_group_or_others_is_refused(tmp_path: Path, mode: int) -> None:
    path = write_key_file(tmp_path, KEY_FILE, mode)
    with pytest.raises(KeyFileError, match="chmod 600") as info:
        load_key_file(path)
    assert oct(mode)[2:] in str(info.value)
    assert "no keys were loaded" in str(info.value)


def test_malformed_hex_is_reported_without_the_value(tmp_path: Path) -> None:
    secret_looking = "zz" + KEY_1.hex()[2:]
    text = f'[[train]]\nid = 5\n[train.keys]\n1 = "{secret_looking}"\n'
    with pytest.raises(KeyFileError) as info:
        load_key_file(write_key_file(tmp_path, text))
    assert secret_looking not in str(info.value)
    assert KEY_1.hex()[2:] not in str(info.value)


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ('id = "{key}"', "train[0]: id must be an integer train id, got a str"),
        (
            'id = 5\nactive_key = "{key}"',
            "train[0]: active_key must be an integer key id, got a str",
        ),
        ("id = 5\nactive_key = 1.0", "train[0]: active_key must be an integer key id, got 1.0"),
        ("active_key = 1", "train[0]: id must be an integer train id, got nothing"),
    ],
)
def test_a_key_of_the_wrong_type_is_named_and_a_string_only_by_its_type(
    tmp_path: Path, entry: str, message: str
) -> None:
    key = KEY_1.hex()
    text = "[[train]]\n" + entry.format(key=key) + f'\n[train.keys]\n1 = "{key}"\n'
    with pytest.raises(KeyFileError) as info:
        load_key_file(write_key_file(tmp_path, text))
    assert message in str(info.value)
    assert key not in str(info.value)


def test_a_key_that_is_no_string_is_named_by_its_id(tmp_path: Path) -> None:
    text = "[[train]]\nid = 5\n[train.keys]\n1 = 7\n"
    with pytest.raises(KeyFileError, match="train\\[0\\]: key '1' must be a hex string"):
        load_key_file(write_key_file(tmp_path, text))


def test_short_key_is_reported_by_length_only(tmp_path: Path) -> None:
    text = '[[train]]\nid = 5\n[train.keys]\n1 = "00112233"\n'
    with pytest.raises(KeyFileError, match="length") as info:
        load_key_file(write_key_file(tmp_path, text))
    assert "00112233" not in str(info.value)


def test_active_key_that_is_not_installed_is_refused(tmp_path: Path) -> None:
    text = f'[[train]]\nid = 5\nactive_key = 3\n[train.keys]\n1 = "{KEY_1.hex()}"\n'
    with pytest.raises(KeyFileError, match="active_key"):
        load_key_file(write_key_file(tmp_path, text))


def test_missing_key_file_is_a_key_file_error(tmp_path: Path) -> None:
    with pytest.raises(KeyFileError, match="cannot read"):
        load_key_file(tmp_path / "absent.toml")


def test_invalid_toml_is_a_key_file_error(tmp_path: Path) -> None:
    with pytest.raises(KeyFileError, match="TOML"):
        load_key_file(write_key_file(tmp_path, "[[train]\n"))


def test_repr_shows_key_ids_but_never_keys() -> None:
    store = KeyStore()
    store.add_key(1001, 1, KEY_1)
    text = repr(store)
    assert "1001" in text and KEY_1.hex() not in text and str(KEY_1) not in text


def test_active_key_cannot_be_removed() -> None:
    store = KeyStore()
    store.add_key(1001, 1, KEY_1)
    with pytest.raises(LinkConfigError, match="rotate first"):
        store.remove_key(1001, 1)


def test_rotation_switches_the_sending_key_and_keeps_the_old_one_acceptable() -> None:
    store = KeyStore()
    store.add_key(1001, 1, KEY_1)
    store.add_key(1001, 2, KEY_2)
    store.set_active(1001, 2)
    assert store.active(1001) == (2, KEY_2)
    assert store.lookup(1001, 1) == KEY_1
    store.remove_key(1001, 1)
    assert store.lookup(1001, 1) is None


def test_key_id_zero_is_reserved_for_unauthenticated_frames() -> None:
    with pytest.raises(LinkConfigError, match="key_id"):
        KeyStore().add_key(1001, 0, KEY_1)
