"""A dispatcher's token survives a restart without being typed on the command line: a token
file (created with mode 0600 when missing, refused when others may read it or when its token
is too short) or the RAILPILOT_TOKEN environment variable (docs/dashboard.md, "Token and
binding")."""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

import pytest

from railpilot.cli import main
from railpilot.errors import ConfigError
from railpilot.web.token import MIN_TOKEN_CHARS, TOKEN_ENV, dispatcher_token

GOOD = "a-dispatcher-token-of-the-night-shift"
assert len(GOOD) >= MIN_TOKEN_CHARS


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _token_file(path: Path, text: str, mode: int) -> Path:
    path.write_text(text, encoding="utf-8")
    path.chmod(mode)
    return path


# --- the library: where the token comes from -------------------------------------------------


def test_a_missing_token_file_gets_a_new_token_written_with_mode_0600(tmp_path: Path) -> None:
    path = tmp_path / "dispatcher.token"
    token = dispatcher_token(None, {}, path)
    assert not path.exists()  # written once the server is up, not before
    token.save()
    assert _mode(path) == 0o600
    assert path.read_text(encoding="utf-8").strip() == token.value
    assert len(token.value) >= MIN_TOKEN_CHARS


def test_the_same_token_after_a_restart(tmp_path: Path) -> None:
    path = tmp_path / "dispatcher.token"
    first = dispatcher_token(None, {}, path)
    first.save()
    second = dispatcher_token(None, {}, path)  # the server again, later
    second.save()  # an existing file is kept as it is
    assert second.value == first.value
    assert (second.origin, second.new_file) == ("file", False)
    assert path.read_text(encoding="utf-8").strip() == first.value


def test_a_new_token_file_is_0600_whatever_the_umask(tmp_path: Path) -> None:
    old = os.umask(0)
    try:
        token = dispatcher_token(None, {}, tmp_path / "t")
        token.save()
    finally:
        os.umask(old)
    assert _mode(tmp_path / "t") == 0o600


@pytest.mark.parametrize("mode", [0o644, 0o640, 0o604, 0o660])
def test_a_token_file_others_may_read_is_refused(tmp_path: Path, mode: int) -> None:
    path = _token_file(tmp_path / "t", GOOD + "\n", mode)
    with pytest.raises(ConfigError) as caught:
        dispatcher_token(None, {}, path)
    message = str(caught.value)
    assert "--token-file" in message and f"{mode:04o}" in message and "0600" in message
    assert GOOD not in message


def test_a_token_file_with_a_short_token_is_refused(tmp_path: Path) -> None:
    path = _token_file(tmp_path / "t", "short\n", 0o600)
    with pytest.raises(ConfigError, match=f"--token-file .*at least {MIN_TOKEN_CHARS}"):
        dispatcher_token(None, {}, path)


def test_a_token_file_in_a_missing_folder_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"--token-file .*is not a folder"):
        dispatcher_token(None, {}, tmp_path / "no-such-folder" / "t")


def test_the_environment_variable_is_taken(tmp_path: Path) -> None:
    token = dispatcher_token(None, {TOKEN_ENV: GOOD}, None)
    assert (token.value, token.origin) == (GOOD, "environment")
    assert GOOD not in token.shown() and GOOD not in repr(token)


def test_an_empty_environment_variable_is_not_a_token(tmp_path: Path) -> None:
    assert dispatcher_token(None, {TOKEN_ENV: ""}, None).origin == "generated"


def test_a_short_environment_token_is_refused_without_showing_it() -> None:
    with pytest.raises(ConfigError) as caught:
        dispatcher_token(None, {TOKEN_ENV: "short-one"}, None)
    assert TOKEN_ENV in str(caught.value) and "short-one" not in str(caught.value)


def test_precedence_option_then_environment_then_file(tmp_path: Path) -> None:
    path = _token_file(tmp_path / "t", "from-the-token-file-0123\n", 0o600)
    environ = {TOKEN_ENV: GOOD}
    assert dispatcher_token("from-the-option-0123456", environ, None).origin == "option"
    assert dispatcher_token(None, environ, path).value == GOOD
    assert dispatcher_token(None, {}, path).value == "from-the-token-file-0123"
    with pytest.raises(ConfigError, match=r"--token-file .*not given with --dispatcher-token"):
        dispatcher_token("from-the-option-0123456", {}, path)


# --- the command line ------------------------------------------------------------------------

SERVE = ["ground", "serve", "--no-auth", "--db", ":memory:", "--port", "0", "--admin-port", "-1"]


def _serve_once(*extra: str) -> int:
    """``ground serve`` with a dashboard, stopped once it has printed its address."""
    return main([*SERVE, "--http-port", "0", "--seconds", "0.2", *extra])


def _dashboard_line(err: str) -> str:
    [line] = [x for x in err.splitlines() if x.startswith("dashboard: ")]
    return line


def test_serve_creates_the_token_file_and_reads_it_after_a_restart(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    path = tmp_path / "dispatcher.token"
    assert _serve_once("--token-file", str(path)) == 0
    first = _dashboard_line(capsys.readouterr().err)
    assert _mode(path) == 0o600
    token = path.read_text(encoding="utf-8").strip()
    assert re.search(rf"token: \(a new one, written to {re.escape(str(path))}\)$", first)
    assert token not in first  # the start line says where it is, never what

    assert _serve_once("--token-file", str(path)) == 0  # the restart
    second = _dashboard_line(capsys.readouterr().err)
    assert second.endswith(f"token: (the one in {path})")
    assert path.read_text(encoding="utf-8").strip() == token


def test_serve_refuses_a_token_file_others_may_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    path = _token_file(tmp_path / "t", GOOD + "\n", 0o644)
    assert _serve_once("--token-file", str(path)) == 2
    out, err = capsys.readouterr()
    [error] = [x for x in err.splitlines() if x.startswith("railpilot: error: ")]
    assert f"--token-file = '{path}'" in error and "0644" in error
    assert "dashboard:" not in err and GOOD not in out + err
    assert _mode(path) == 0o644  # left as it was


def test_serve_refuses_a_token_file_given_without_a_dashboard(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*SERVE, "--seconds", "0.2", "--token-file", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert "--token-file = " in err and "with --http-port" in err
    assert list(tmp_path.iterdir()) == []


def test_serve_takes_the_token_from_the_environment(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(TOKEN_ENV, GOOD)
    assert _serve_once() == 0
    line = _dashboard_line(capsys.readouterr().err)
    assert line.endswith(f"token: (the one in {TOKEN_ENV})") and GOOD not in line
