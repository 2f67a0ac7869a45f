"""Bad input to the ground, onboard and link commands: exit code 2, an error naming the
option, the value and what is allowed, and nothing left behind (no store file created by a
server that did not start)."""

from __future__ import annotations

import errno
import os
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import railpilot.commands.link as link_commands
from railpilot.cli import main
from railpilot.ground.store import open_store

KEY_HEX = "ab" * 32


@pytest.fixture
def busy_port() -> Iterator[int]:
    """A port on 127.0.0.1 that another socket is listening on."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen(1)
        yield int(sock.getsockname()[1])


@pytest.fixture
def never_run(monkeypatch: pytest.MonkeyPatch) -> None:
    """A command that gets past its checks fails the test at once instead of running."""

    def refuse(coroutine: Any) -> None:
        coroutine.close()
        raise AssertionError("the command started although its input is bad")

    monkeypatch.setattr(link_commands, "_run_async", refuse)


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    lines = [line for line in err.splitlines() if line.startswith("railpilot: error: ")]
    assert len(lines) == 1, err
    return lines[0]


def _serve(db: Path, *extra: str) -> list[str]:
    return ["ground", "serve", "--no-auth", "--seconds", "5", "--db", str(db), *extra]


# --- 1. a server that cannot listen: exit 2 naming the option, no new store left ------------


@pytest.mark.parametrize(
    ("option", "value", "reason"),
    [
        ("--host", "192.0.2.1", "assign requested address"),  # TEST-NET-1: not this host's
    ],
)
def test_serve_on_a_host_it_cannot_listen_on_is_refused_and_leaves_no_store(
    option: str, value: str, reason: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "ground.db"
    argv = _serve(db, "--port", "0", "--admin-port", "-1", option, value)
    assert main(argv) == 2
    error = _error(capsys)
    assert f"{option} = {value!r}" in error and reason in error
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("option", ["--port", "--admin-port", "--http-port"])
def test_serve_on_a_busy_port_is_refused_and_leaves_no_store(
    option: str, busy_port: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "ground.db"
    ports = {"--port": "0", "--admin-port": "0", option: str(busy_port)}
    argv = _serve(db, *(x for item in ports.items() for x in item))
    assert main(argv) == 2
    error = _error(capsys)
    assert f"{option} = {busy_port}" in error and "in use" in error
    assert list(tmp_path.iterdir()) == []


def test_a_store_that_was_there_is_kept_when_the_server_cannot_start(
    busy_port: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "ground.db"
    open_store(str(db)).close()
    before = db.read_bytes()
    assert main(_serve(db, "--port", str(busy_port), "--admin-port", "-1")) == 2
    assert "--port" in _error(capsys)
    assert db.read_bytes() == before


def test_a_proxy_on_a_busy_port_is_refused_naming_listen(
    busy_port: int, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["link", "proxy", "--listen", f"127.0.0.1:{busy_port}", "--upstream", "127.0.0.1:1"]
    assert main([*argv, "--seconds", "5"]) == 2
    error = _error(capsys)
    assert f"--listen = '127.0.0.1:{busy_port}'" in error and "in use" in error


# --- 2. the admin client's --admin-port ------------------------------------------------------

ADMIN_COMMANDS = [
    ["ground", "status"],
    ["ground", "tsr", "set", "--start-km", "1", "--end-km", "2", "--limit-kmh", "45"],
    ["ground", "tsr", "cancel", "--session", "1"],
    ["ground", "restriction", "set", "--block", "B1"],
    ["ground", "restriction", "clear", "--id", "1"],
    ["ground", "target", "--train", "5", "--km", "10"],
    ["ground", "dispatch", "--train", "5", "--text", "hold"],
]


@pytest.mark.parametrize("port", ["-1", "70000", "0"])
@pytest.mark.parametrize("argv", ADMIN_COMMANDS, ids=lambda a: " ".join(a[1:3]))
def test_an_admin_port_out_of_range_is_refused(
    argv: list[str], port: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*argv, "--admin-port", port]) == 2
    error = _error(capsys)
    assert f"--admin-port = {port}" in error and "65535" in error


# --- 3. a key file whose active_key is not an integer ----------------------------------------


@pytest.mark.parametrize("active", ["inf", "nan", "true", "1.0", '"1"'])
@pytest.mark.parametrize(
    "argv",
    [
        ["link", "decode", "-"],
        ["onboard", "run", "--server", "127.0.0.1:1", "--train-id", "5", "--seconds", "5"],
        ["ground", "serve", "--port", "0", "--admin-port", "-1", "--seconds", "5"],
    ],
    ids=["decode", "onboard", "ground"],
)
def test_a_key_file_with_an_active_key_that_is_not_an_integer_is_refused(
    argv: list[str],
    active: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    never_run: None,
) -> None:
    keys = tmp_path / "keys.toml"
    keys.write_text(f'[[train]]\nid = 5\nactive_key = {active}\n[train.keys]\n1 = "{KEY_HEX}"\n')
    keys.chmod(0o600)
    extra = ["--db", str(tmp_path / "ground.db")] if argv[0] == "ground" else []
    assert main([*argv, *extra, "--keys", str(keys)]) == 2
    error = _error(capsys)
    assert "train[0]" in error and "active_key" in error
    assert KEY_HEX[:16] not in error
    assert not (tmp_path / "ground.db").exists()


# --- 4. onboard values the link messages would refuse ----------------------------------------


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--speed-kmh", "nan"),
        ("--speed-kmh", "400"),
        ("--decel", "inf"),
        ("--decel", "nan"),
        ("--start-km", "nan"),
        ("--start-km", "inf"),
        ("--start-km", "-1"),
        ("--loco-number", "é日本"),
        ("--loco-number", "A B"),
        ("--loco-number", "SS4-00001"),
        ("--train-number", "K\t1"),
        ("--train-number", ""),
        ("--length-m", "nan"),
    ],
)
def test_onboard_values_a_link_message_cannot_carry_are_refused_up_front(
    option: str, value: str, capsys: pytest.CaptureFixture[str], never_run: None
) -> None:
    argv = ["onboard", "run", "--no-auth", "--server", "127.0.0.1:1", "--train-id", "5"]
    assert main([*argv, "--seconds", "2", option, value]) == 2
    error = _error(capsys)
    assert f"{option} = " in error and "expected" in error


# --- 5. --seconds: a finite number > 0 -------------------------------------------------------


@pytest.mark.parametrize("seconds", ["nan", "-1", "0", "inf", "1e308"])
@pytest.mark.parametrize(
    "argv",
    [
        ["ground", "serve", "--no-auth", "--port", "0", "--admin-port", "-1"],
        ["onboard", "run", "--no-auth", "--server", "127.0.0.1:1", "--train-id", "5"],
        ["link", "proxy", "--listen", "127.0.0.1:0", "--upstream", "127.0.0.1:1"],
        ["link", "loadtest", "--trains", "1"],
    ],
    ids=["ground", "onboard", "proxy", "loadtest"],
)
def test_seconds_must_be_a_finite_number_above_zero(
    argv: list[str],
    seconds: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    never_run: None,
) -> None:
    import railpilot.rigs.loadtest as loadtest

    def refuse(options: Any) -> None:
        raise AssertionError("the load test started although its input is bad")

    monkeypatch.setattr(loadtest, "run_loadtest", refuse)
    extra = ["--db", str(tmp_path / "ground.db")] if argv[0] == "ground" else []
    assert main([*argv, *extra, "--seconds", seconds]) == 2
    error = _error(capsys)
    assert "--seconds = " in error and "expected" in error
    assert list(tmp_path.iterdir()) == []


# --- 6. the proxy's --inject: a readable file, or wire bytes in hex ------------------------

PROXY = ["link", "proxy", "--listen", "127.0.0.1:0", "--upstream", "127.0.0.1:1"]


@pytest.mark.parametrize(
    ("name", "problem"),
    [
        ("frame.bin", "no such file, and not hex"),  # a mistyped name: was sent as its letters
        ("a_dir", "it is a directory"),
        ("empty.bin", "the file is empty"),
        ("unreadable.bin", "the file cannot be read (Permission denied)"),
        ("", "no such file, and not hex"),
    ],
)
def test_an_inject_that_is_no_readable_file_and_no_hex_is_refused(
    name: str,
    problem: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    never_run: None,
) -> None:
    (tmp_path / "a_dir").mkdir()
    (tmp_path / "empty.bin").write_bytes(b"")
    unreadable = tmp_path / "unreadable.bin"
    unreadable.write_bytes(b"\x7e\x01")
    unreadable.chmod(0)
    read_bytes = Path.read_bytes

    def as_for_anyone_but_root(path: Path) -> bytes:  # root may read it after all
        if path == unreadable:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return read_bytes(path)

    monkeypatch.setattr(Path, "read_bytes", as_for_anyone_but_root)
    value = str(tmp_path / name) if name else ""
    assert main([*PROXY, "--seconds", "5", "--inject", value]) == 2
    error = _error(capsys)
    assert (
        f"--inject = {value!r} is not allowed: expected a readable file, or wire bytes in hex"
        in error
    )
    assert problem in error
    # the proxy is no link endpoint: its refusals say what did not happen to it
    assert error.rstrip().endswith("the proxy was not started")


@pytest.mark.parametrize(
    ("value", "wire"),
    [
        ("7e 01:0x02", b"\x7e\x01\x02"),
        ("ab" * 200, b"\xab" * 200),  # longer than a file name may be: hex, not an error
        ("hex.txt", b"\x7e\x01\x02"),  # hex text in a file: the bytes it spells
        ("raw.bin", b"\x7e\x01zz"),  # anything else in a file: its bytes
    ],
)
def test_an_inject_file_gives_its_bytes_and_hex_gives_the_bytes_it_spells(
    value: str, wire: bytes, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import railpilot.net.proxy as proxy

    (tmp_path / "hex.txt").write_text("# a frame\n7e 01\n02\n")
    (tmp_path / "raw.bin").write_bytes(b"\x7e\x01zz")
    monkeypatch.chdir(tmp_path)
    made: list[Any] = []
    real = proxy.ProxyOptions

    def options(**fields: Any) -> Any:
        made.append(real(**fields))
        return made[-1]

    def started(coroutine: Any) -> dict[str, Any]:  # what the proxy would do: nothing here
        coroutine.close()
        return {"up": {}, "down": {}}

    monkeypatch.setattr(proxy, "ProxyOptions", options)
    monkeypatch.setattr(link_commands, "_run_async", started)
    assert main([*PROXY, "--seconds", "5", "--inject", value]) == 0
    assert [o.inject for o in made] == [wire]


def test_inject_hex_that_does_not_pair_up_is_refused_naming_where(
    capsys: pytest.CaptureFixture[str], never_run: None
) -> None:
    assert main([*PROXY, "--seconds", "5", "--inject", "7e 0"]) == 2
    error = _error(capsys)
    assert "--inject: line 1, column 4: odd number of hex digits" in error


# --- 7. --no-auth and --keys: one or the other --------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ["ground", "serve", "--port", "0", "--admin-port", "-1", "--seconds", "5"],
        ["onboard", "run", "--server", "127.0.0.1:1", "--train-id", "5", "--seconds", "5"],
    ],
    ids=["ground", "onboard"],
)
def test_no_auth_with_a_key_file_is_refused(
    argv: list[str],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    never_run: None,
) -> None:
    import railpilot.link as link

    keys = tmp_path / "keys.toml"
    keys.write_text(f'[[train]]\nid = 5\nactive_key = 1\n[train.keys]\n1 = "{KEY_HEX}"\n')
    keys.chmod(0o600)
    read: list[Any] = []
    monkeypatch.setattr(link, "load_key_file", lambda path: read.append(path))
    extra = ["--db", str(tmp_path / "ground.db")] if argv[0] == "ground" else []
    assert main([*argv, *extra, "--keys", str(keys), "--no-auth"]) == 2
    error = _error(capsys)
    assert f"--no-auth = 'with --keys {keys}' is not allowed" in error
    assert "one or the other" in error
    assert read == []  # refused before the key file is read
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keys.toml"]  # no store
