"""The optional parts of railpilot and the extra that installs each.

The core (simulation, link protocol, line runs, the command line) needs none of them; a
command that does needs its extra, and says so before it starts:

* ``web`` - the dispatcher dashboard (``ground serve --http-port``, ``link loadtest
  --dashboard``, ``reproduce dashboard``): Starlette, uvicorn, websockets;
* ``postgres`` - the ground store on a PostgreSQL server (``ground serve --db
  postgresql://...``): psycopg;
* ``cluster`` - sweeps on a Dask cluster (``--scheduler``): dask.distributed.

``pip install 'railpilot[web,postgres,cluster]'`` installs them all (``make`` does).
"""

from __future__ import annotations

import importlib.util
from typing import Any, Final

from railpilot.errors import ConfigError

#: extra -> the top-level modules it provides (what its code imports).
EXTRAS: Final[dict[str, tuple[str, ...]]] = {
    "web": ("starlette", "uvicorn", "websockets"),
    "postgres": ("psycopg",),
    "cluster": ("dask", "distributed"),
}


def install_hint(extra: str) -> str:
    """How to install ``extra``: ``pip install 'railpilot[EXTRA]'``."""
    return f"pip install 'railpilot[{extra}]'"


def missing(extra: str) -> list[str]:
    """The modules of ``extra`` that cannot be imported here (none when it is installed)."""
    return [name for name in EXTRAS[extra] if not _importable(name)]


def require(extra: str, field: str, value: Any) -> None:
    """Refuse ``field = value`` (a :class:`ConfigError`, before anything starts) when the
    part it asks for is not installed, naming the extra that installs it."""
    absent = missing(extra)
    if absent:
        raise ConfigError(
            field,
            value,
            f"railpilot's '{extra}' extra installed ({', '.join(absent)} missing): "
            f"{install_hint(extra)}",
        )


def extra_of(error: ModuleNotFoundError) -> str | None:
    """The extra that provides the module ``error`` did not find, or None."""
    top = (error.name or "").partition(".")[0]
    return next((extra for extra, names in EXTRAS.items() if top in names), None)


def _importable(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):  # a broken or half-installed package
        return False
