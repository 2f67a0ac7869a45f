"""Where a sweep's runs go: the Dask cluster the command line names (``--scheduler``),
or this machine's cores.

``railpilot montecarlo`` and ``railpilot line simulate --runs`` share :func:`dask_client`,
so an address that is malformed or where no scheduler answers gives the same clear error
in both, before any run starts, instead of Dask's traceback. :func:`fan_out` runs many
independent calls on either and hands back each result as its call ends.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, TypeVar

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


Result = TypeVar("Result")


def fan_out(
    function: Callable[..., Result],
    calls: Sequence[tuple[Any, ...]],
    scheduler: str | None = None,
    option: str = "--scheduler",
) -> Iterator[tuple[int, Result]]:
    """``function(*calls[k])`` for every ``k``, each in a process of its own, yielded as
    ``(k, result)`` in the order the calls end (a long sweep can say how far it is).

    Without ``scheduler``, on a pool of fresh (spawned) processes, one per core (at most
    one per call); with it, on the Dask cluster at that address (:func:`dask_client`,
    ``option`` named in its errors). ``function`` and its arguments must pickle: a module
    level function whose arguments are plain data. A call that raises raises here.
    """
    if not calls:
        return
    if scheduler is None:
        yield from _on_this_machine(function, calls)
        return
    from dask.distributed import as_completed

    with dask_client(scheduler, option) as client:
        columns = [list(column) for column in zip(*calls, strict=True)]
        submitted = client.map(function, *columns, pure=False)
        index_of = {future.key: k for k, future in enumerate(submitted)}
        for future in as_completed(submitted):
            yield index_of[future.key], future.result()


def _on_this_machine(
    function: Callable[..., Result], calls: Sequence[tuple[Any, ...]]
) -> Iterator[tuple[int, Result]]:
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor, as_completed

    workers = min(os.cpu_count() or 1, len(calls))
    # spawned, not forked: a worker starts from a clean interpreter, as a Dask worker does
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context) as pool:
        index_of = {pool.submit(function, *call): k for k, call in enumerate(calls)}
        for future in as_completed(index_of):
            yield index_of[future], future.result()
