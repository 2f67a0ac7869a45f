"""The compiled loop comes from Numba's on-disk cache in a new process.

The loop is specialised for the controller's and the brake's steps; before
railpilot/jit_identity.py (built-in steps) and control/user.py ``step_pointer`` (a
user's step), every process compiled it again: several seconds for each pair, in every
train process of a live line run, every Dask worker and every command. Each case runs
twice in fresh processes: the first fills the cache if it has to, the second must find
the loop there and compile nothing.
"""

from __future__ import annotations

import pytest

from child_process import ROOT, run_python_json

PAPER002 = ROOT / "examples" / "paper002_qsmc_stop.toml"
EXAMPLE = ROOT / "examples" / "user_controller.py"

CHILD = """
import json, sys
from dataclasses import replace
from railpilot.control.user import load_controller
from railpilot.scenario import load_scenario
from railpilot.sim import engine
from railpilot.sim.run import simulate

s = load_scenario(sys.argv[1])
s = replace(s, sim=replace(s.sim, duration_s=5.0))
simulate(s, load_controller(sys.argv[2]) if len(sys.argv) > 2 else None)
stats = engine.run_kernel.stats
print(json.dumps({"hits": stats.cache_hits.total(), "misses": stats.cache_misses.total()}))
"""


def _loop_cache_stats(*args: str) -> dict[str, int]:
    return run_python_json(CHILD, *args)


@pytest.mark.parametrize(
    "controller",
    [
        pytest.param((), id="built-in"),
        pytest.param((f"{EXAMPLE}:CompiledTracker",), id="user-compiled"),
        pytest.param((f"{EXAMPLE}:SpeedPositionTracker",), id="user-python"),
    ],
)
@pytest.mark.slow
def test_a_new_process_loads_the_loop_instead_of_compiling_it(controller: tuple[str, ...]) -> None:
    _loop_cache_stats(str(PAPER002), *controller)  # fills the cache if it is empty
    assert _loop_cache_stats(str(PAPER002), *controller) == {"hits": 1, "misses": 0}


def test_a_steps_identity_follows_its_source() -> None:
    from numba import njit

    from railpilot.control.registry import CONTROLLERS
    from railpilot.jit_identity import same_in_every_process

    pid = CONTROLLERS["pid"].step
    assert same_in_every_process(pid) is pid  # a second call keeps the identity it has

    def make(scale: float):  # type: ignore[no-untyped-def]
        def step(x):  # type: ignore[no-untyped-def]
            return x * scale

        return step

    a = same_in_every_process(njit(make(2.0)))
    b = same_in_every_process(njit(make(2.0)))
    assert a._uuid == b._uuid  # the same name and source: the same identity, every time
    assert a._uuid != pid._uuid
