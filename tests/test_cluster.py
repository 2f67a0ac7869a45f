"""railpilot.cluster: the Dask cluster a sweep names with --scheduler."""

from __future__ import annotations

import socket

import pytest

from railpilot.cluster import dask_client
from railpilot.errors import ConfigError

distributed = pytest.importorskip("dask.distributed")


@pytest.mark.parametrize(
    "address", ["", "no-port", "xyz://127.0.0.1:8786", "tcp://127.0.0.1:x", "127.0.0.1:70000"]
)
def test_an_address_dask_cannot_read_is_refused_naming_the_option(address: str) -> None:
    with pytest.raises(ConfigError) as info, dask_client(address):
        pass
    assert info.value.field == "--scheduler" and info.value.value == address


def test_an_address_where_nothing_answers_is_refused_with_dask_s_reason() -> None:
    # a port just closed on loopback: refused at once
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    with pytest.raises(ConfigError) as info, dask_client(address, option="--cluster"):
        pass
    assert info.value.field == "--cluster" and info.value.value == address
    assert "Dask scheduler" in info.value.allowed and "refused" in info.value.allowed


def test_a_running_scheduler_gives_a_client_that_runs_work_and_is_closed_after() -> None:
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        with dask_client(cluster.scheduler_address) as client:
            assert client.submit(pow, 3, 4).result(timeout=60) == 81
        assert client.status == "closed"


CALLS = [(2, 3), (3, 2), (5, 0), (7, 1)]


def test_fan_out_on_this_machine_gives_each_call_its_own_result() -> None:
    from railpilot.cluster import fan_out

    done = list(fan_out(pow, CALLS))
    assert sorted(k for k, _ in done) == list(range(len(CALLS)))
    assert dict(done) == {k: pow(*call) for k, call in enumerate(CALLS)}
    assert list(fan_out(pow, [])) == []


def test_fan_out_on_a_cluster_gives_what_this_machine_gives() -> None:
    from railpilot.cluster import fan_out

    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        done = dict(fan_out(pow, CALLS, cluster.scheduler_address))
    assert done == dict(fan_out(pow, CALLS))


def test_fan_out_names_the_option_for_a_bad_scheduler() -> None:
    from railpilot.cluster import fan_out

    with pytest.raises(ConfigError) as info:
        list(fan_out(pow, CALLS, "no-port", option="--cluster"))
    assert info.value.field == "--cluster"
