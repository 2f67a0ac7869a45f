"""A throwaway PostgreSQL server for the store tests (docs/ground-store.md).

Debian's binaries (``/usr/lib/postgresql/*/bin``; .ci/run installs the ``postgresql``
package), a cluster initialised in a temporary directory, listening on 127.0.0.1 on a
free port with its unix socket in that directory, stopped (``pg_ctl stop -m fast``) and
removed at the end of the session, also when a test failed. PostgreSQL refuses to run as
root, so as root every server command runs as the ``postgres`` user (``runuser``), on a
directory that user owns. Host connections need the superuser's password (SCRAM), so
every DSN the tests use carries a password the store must never show.

``postgres_server`` (session) starts it or skips: ``PostgreSQL not available: <why>``;
``postgres_dsn`` gives each test a database of its own. Import both into a conftest or a
test module to use them.
"""

from __future__ import annotations

import glob
import os
import pwd
import secrets
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import count
from pathlib import Path
from typing import Any

import pytest

BIN_GLOB = "/usr/lib/postgresql/*/bin"
SUPERUSER = "postgres"
#: pg_ctl's own bound on a start or stop (it polls the server; we never sleep).
PG_CTL_WAIT_S = 60
#: A free port may be taken between our probe and the server's bind: try another.
START_ATTEMPTS = 3


@dataclass(frozen=True)
class PostgresServer:
    port: int
    password: str
    data: Path

    def dsn(self, dbname: str = "postgres") -> str:
        return f"postgresql://{SUPERUSER}:{self.password}@127.0.0.1:{self.port}/{dbname}"

    def execute(self, sql: str, dbname: str = "postgres") -> list[tuple[Any, ...]]:
        """One statement as the superuser, outside any transaction (CREATE DATABASE ...)."""
        import psycopg

        with psycopg.connect(self.dsn(dbname), autocommit=True) as db:
            cursor = db.execute(sql.encode())
            return cursor.fetchall() if cursor.description else []


def _bin_dir() -> Path:
    """The newest installed PostgreSQL's bin directory (or skip)."""
    found = [Path(p) for p in glob.glob(BIN_GLOB) if (Path(p) / "initdb").is_file()]
    if not found:
        pytest.skip(
            f"PostgreSQL not available: no initdb under {BIN_GLOB} (apt-get install postgresql)"
        )

    def version(bin_dir: Path) -> tuple[int, ...]:  # /usr/lib/postgresql/15/bin -> (15,)
        number = bin_dir.parent.name
        return tuple(map(int, number.split("."))) if number.replace(".", "").isdigit() else ()

    return max(found, key=version)


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _run(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, check=False)


def _tail(path: Path, lines: int = 5) -> str:
    text = path.read_text(errors="replace") if path.is_file() else ""
    return " | ".join(text.strip().splitlines()[-lines:])


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[PostgresServer]:
    try:
        import psycopg  # noqa: F401
    except ModuleNotFoundError:
        pytest.skip("PostgreSQL not available: psycopg is not installed")
    bin_dir = _bin_dir()
    as_user: list[str] = []
    owner: pwd.struct_passwd | None = None
    if os.geteuid() == 0:  # postgres: "root execution of the PostgreSQL server is not permitted"
        try:
            owner = pwd.getpwnam(SUPERUSER)
        except KeyError:
            pytest.skip(f"PostgreSQL not available: running as root and no {SUPERUSER!r} user")
        runuser = shutil.which("runuser")
        if runuser is None:
            pytest.skip("PostgreSQL not available: running as root and no runuser")
        as_user = [runuser, "-u", SUPERUSER, "--"]
    # Not under pytest's tmp_path: its parents are private to root, and the server (as
    # the postgres user) must reach its data directory and socket.
    base = Path(tempfile.mkdtemp(prefix="railpilot-pg-"))
    data, log = base / "data", base / "server.log"
    password = secrets.token_hex(16)
    pwfile = base / "pwfile"
    pwfile.write_text(password + "\n")
    if owner is not None:
        for path in (base, pwfile):
            os.chown(path, owner.pw_uid, owner.pw_gid)
    started = False
    try:
        initdb = _run(
            [
                *as_user,
                str(bin_dir / "initdb"),
                *("-D", str(data), "-U", SUPERUSER, "--pwfile", str(pwfile)),
                *("--auth-local=trust", "--auth-host=scram-sha-256"),
                *("--encoding=UTF8", "--no-locale", "--no-sync"),
            ],
            cwd=base,
        )
        if initdb.returncode != 0:
            why = " | ".join(initdb.stderr.strip().splitlines()[-3:])
            pytest.skip(f"PostgreSQL not available: initdb failed ({why})")
        for _ in range(START_ATTEMPTS):
            port = _free_port()
            options = (
                f"-c listen_addresses=127.0.0.1 -c port={port} -c unix_socket_directories={base}"
            )
            start = _run(
                [
                    *as_user,
                    str(bin_dir / "pg_ctl"),
                    *("start", "-w", "-t", str(PG_CTL_WAIT_S)),
                    *("-D", str(data), "-l", str(log), "-o", options),
                ],
                cwd=base,
            )
            if start.returncode == 0:
                started = True
                break
        if not started:
            pytest.skip(f"PostgreSQL not available: pg_ctl start failed ({_tail(log)})")
        yield PostgresServer(port, password, data)
    finally:
        if started:
            _run(
                [
                    *as_user,
                    str(bin_dir / "pg_ctl"),
                    *("stop", "-w", "-t", str(PG_CTL_WAIT_S), "-m", "fast", "-D", str(data)),
                ],
                cwd=base,
            )
        shutil.rmtree(base, ignore_errors=True)


_databases = count(1)


@pytest.fixture
def postgres_dsn(postgres_server: PostgresServer) -> Iterator[str]:
    """A fresh, empty database on the test server; its URL (with the password)."""
    name = f"ground_{next(_databases)}"
    postgres_server.execute(f'CREATE DATABASE "{name}"')
    yield postgres_server.dsn(name)
    # FORCE: a store a failed test left open must not keep the database
    postgres_server.execute(f'DROP DATABASE "{name}" WITH (FORCE)')
