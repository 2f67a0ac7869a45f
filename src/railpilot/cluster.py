"""The Dask cluster a sweep runs on when the command line names one (``--scheduler``).

``railpilot montecarlo`` and ``railpilot line simulate --runs`` share it, so an address
that is malformed or where no scheduler answers gives the same clear error in both,
before any run starts, instead of Dask's traceback.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from railpilot.errors import ConfigError

if TYPE_CHECKING:
    from dask.distributed import Client

#: how long to wait for the scheduler to answer [s] (Dask's own default)
CONNECT_TIMEOUT_S = 30.0
ALLOWED = "the address of a running Dask scheduler, e.g. tcp://127.0.0.1:8786"


@contextmanager
def dask_client(
    address: str, option: str = "--scheduler", timeout_s: float = CONNECT_TIMEOUT_S
) -> Iterator[Client]:
    """A client connected to the scheduler at ``address`` (``[SCHEME://]HOST:PORT``),
    closed on leaving.

    A malformed address or one where nothing answers within ``timeout_s`` [s] is a
    :class:`ConfigError` naming ``option`` and the address, with the reason.
    """
    from dask.distributed import Client
    from distributed.comm import get_address_host_port, parse_address

    try:
        if parse_address(address)[0] != "inproc":  # a scheduler in this process has no port
            host, port = get_address_host_port(address)  # a known scheme, a host, a port
            if not 0 < port < 65536:
                raise ValueError(f"port {port} is not a TCP port")
            # Something must listen there before a Client is made: a Client that fails to
            # start leaves an object whose collection later can deadlock the next Client's
            # start in the same process (seen in the test suite, distributed 2026.8).
            with socket.create_connection((host, port), timeout=timeout_s):
                pass
        client = Client(address, timeout=timeout_s)
    except (OSError, ValueError) as error:
        raise ConfigError(option, address, f"{ALLOWED} ({error})") from None
    with client:
        yield client
