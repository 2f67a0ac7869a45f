"""The dispatcher token of a server that serves the dashboard: where it comes from.

The dashboard asks for a token before a dispatcher may set or cancel a TSR
(docs/dashboard.md). ``railpilot ground serve`` takes it from the first of
``--dispatcher-token``, the :data:`TOKEN_ENV` environment variable, a token file (created
with a new token, mode 0600, when missing, so the same token serves after a restart), or
makes one up and prints it once. No network, no web framework: the command line checks the
token before anything starts.
"""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from railpilot.errors import ConfigError

#: Shortest dispatcher token [characters] (e.g. ``secrets.token_urlsafe(16)``: 22).
MIN_TOKEN_CHARS = 16
#: The environment variable a server takes its dispatcher token from (docs/dashboard.md).
TOKEN_ENV = "RAILPILOT_TOKEN"


@dataclass(frozen=True, slots=True, repr=False)
class DispatcherToken:
    """A dispatcher token and where it came from, for a server that serves the dashboard.

    ``origin`` is ``"option"``, ``"environment"``, ``"file"`` or ``"generated"``; ``path``
    the token file (``origin == "file"``) and ``new_file`` whether it is still to be
    written (:meth:`save`, once the server is up: a start that fails writes nothing).
    """

    value: str
    origin: str
    path: Path | None = None
    new_file: bool = False

    def __repr__(self) -> str:  # the token itself stays out of logs and tracebacks
        return f"DispatcherToken(origin={self.origin!r}, path={self.path!r})"

    def save(self) -> None:
        """Write a new token file (mode 0600); nothing for a token from anywhere else."""
        if self.new_file and self.path is not None:
            write_token_file(self.path, self.value)

    def shown(self) -> str:
        """How the server's start line names the token: the token itself only when it was
        made up here and kept nowhere (it is printed once, never logged)."""
        if self.origin == "generated":
            return self.value
        if self.origin == "option":
            return "(the one given with --dispatcher-token)"
        if self.origin == "environment":
            return f"(the one in {TOKEN_ENV})"
        if self.new_file:
            return f"(a new one, written to {self.path})"
        return f"(the one in {self.path})"


def token_problem(token: str) -> str | None:
    """Why ``token`` cannot be a dispatcher token (None: it can)."""
    if len(token) < MIN_TOKEN_CHARS or any(c.isspace() or not c.isprintable() for c in token):
        return f"at least {MIN_TOKEN_CHARS} printable characters without spaces"
    return None


def dispatcher_token(
    option: str | None, environ: Mapping[str, str], token_file: Path | None
) -> DispatcherToken:
    """The dispatcher token of a server, from the first of: ``--dispatcher-token``
    (``option``), the :data:`TOKEN_ENV` environment variable (set and not empty), the
    token file (read; made up, to be saved, when missing), a new random one.

    Raises :class:`ConfigError` naming the source for a token that is too short, a token
    file that others may read or that is not a file, or both options given.
    """
    if option is not None and token_file is not None:
        raise ConfigError(
            "--token-file", str(token_file), "not given with --dispatcher-token (one token)"
        )
    if option is not None:
        if problem := token_problem(option):
            raise ConfigError("--dispatcher-token", "<hidden>", problem)
        return DispatcherToken(option, "option")
    from_env = environ.get(TOKEN_ENV, "")
    if from_env:
        if problem := token_problem(from_env):
            raise ConfigError(TOKEN_ENV, "<hidden>", problem)
        return DispatcherToken(from_env, "environment")
    if token_file is not None:
        kept = read_token_file(token_file)
        if kept is not None:
            return DispatcherToken(kept, "file", token_file)
        return DispatcherToken(secrets.token_urlsafe(16), "file", token_file, new_file=True)
    return DispatcherToken(secrets.token_urlsafe(16), "generated")


def read_token_file(path: Path) -> str | None:
    """The token in a token file (its text without surrounding whitespace); None when there
    is no such file yet and its folder exists (a new one can be written there).

    A token file is refused when its group or others may read or write it (it stands for
    the dispatcher: mode 0600 or 0400), when it is not a regular file, or when the token in
    it is too short (:func:`token_problem`).
    """
    try:
        status = path.stat()
    except FileNotFoundError:
        if not path.parent.is_dir():
            raise ConfigError(
                "--token-file",
                str(path),
                f"a file in an existing folder (created there when missing; {path.parent} "
                "is not a folder)",
            ) from None
        return None
    except OSError as exc:
        raise ConfigError("--token-file", str(path), f"a readable file ({exc})") from None
    if not stat.S_ISREG(status.st_mode):
        raise ConfigError("--token-file", str(path), "a regular file holding the token")
    mode = stat.S_IMODE(status.st_mode)
    if mode & 0o077:
        raise ConfigError(
            "--token-file",
            str(path),
            f"a file only its owner may read (mode 0600; it has {mode:04o}: chmod 600 {path})",
        )
    try:
        token = path.read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError("--token-file", str(path), f"a readable UTF-8 file ({exc})") from None
    if problem := token_problem(token):
        raise ConfigError(
            "--token-file",
            str(path),
            f"a file holding a token of {problem} (it holds {len(token)})",
        )
    return token


def write_token_file(path: Path, token: str) -> None:
    """Write ``token`` to a new file that only its owner may read and write (0600); a file
    that appeared there meanwhile is not overwritten."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        raise ConfigError(
            "--token-file", str(path), f"a new file that can be written ({exc})"
        ) from None
    with os.fdopen(fd, "w", encoding="utf-8") as out:
        os.fchmod(out.fileno(), 0o600)  # whatever the umask
        out.write(token + "\n")
