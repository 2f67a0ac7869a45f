"""Monte Carlo: many runs of one scenario with sampled plant parameters.

The ATO (controller, feed-forward lead, resistance model) is fixed from the nominal
scenario -- it cannot know the sampled plant -- and each run gets its own plant:
mass, delays, lags, resistance, brake effort, outside force and initial speed drawn
from the distributions of the scenario's ``[montecarlo]`` table, and its own seed for
the random disturbance and the speed noise.

Runs go in chunks through one Numba kernel that releases the GIL, a slice of the chunk
per local core on its own thread (the same loop as a single run, on the same
description: sim/layout.py); only each run's scalar metrics are kept (18 floats a run),
never its time series, so memory stays flat however many runs. With a Dask scheduler
address the chunks run on a ``dask.distributed`` cluster instead; every run's
parameters and seed depend only on the spec's seed and the run's index, so a local
and a distributed sweep give the same numbers, bit for bit, and any single run can be
replayed (:func:`replay_scenario`) and plotted.
"""

from __future__ import annotations

import itertools
import os
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np

from railpilot.brakes.ep_blend import EPBrake
from railpilot.brakes.registry import brake_entry_of
from railpilot.control.user import Binding, bind
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.sim import engine
from railpilot.sim.inputs import (
    ato_brake_model,
    batch_inputs,
    line_inputs,
    reference_inputs,
    run_inputs,
)
from railpilot.sim.layout import LineIn, ReferenceIn, RunInputs, RunState, batch_row, stack_runs
from railpilot.sim.run import check_commands, metrics_dict, resolve_controller, run_from_start
from railpilot.sim.sweep import VARIABLE_PARAMETERS, MonteCarloSpec
from railpilot.units import kmh_to_mps, tonne_to_kg

T = TypeVar("T")

if TYPE_CHECKING:  # the simulator never imports the scenario package at run time
    from railpilot.scenario.model import Scenario


def _with(obj: T, **changes: Any) -> T:
    """``dataclasses.replace`` for a field named at run time."""
    return cast(T, replace(cast(Any, obj), **changes))


def _scale_davis(s: Scenario, f: float) -> Scenario:
    t = s.train
    return replace(
        s,
        train=replace(t, davis_a0=t.davis_a0 * f, davis_a1=t.davis_a1 * f, davis_a2=t.davis_a2 * f),
    )


def _delay(s: Scenario, value: float) -> Scenario:
    if isinstance(s.brake, EPBrake) and np.isfinite(value / s.sim.dt_s):
        # the EP brake's delay line works in whole steps: sample at the step's resolution
        # (a value too large to round is left to the brake's own range check)
        value = round(value / s.sim.dt_s) * s.sim.dt_s
    return _brake_field("delay_s")(s, value)


def _brake_field(name: str) -> Callable[[Scenario, float], Scenario]:
    def apply(s: Scenario, value: float) -> Scenario:
        if not hasattr(s.brake, name):
            raise ConfigError(
                f"montecarlo.vary.brake.{name}",
                name,
                f"a parameter of this scenario's brake ({type(s.brake).__name__})",
            )
        return replace(s, brake=_with(s.brake, **{name: value}))

    return apply


def _set(
    field_name: str, convert: Callable[[float], float] = float
) -> Callable[[Scenario, float], Scenario]:
    return lambda s, v: _with(s, **{field_name: convert(v)})


#: How each parameter a sweep can vary (scenario/montecarlo.py lists them) changes
#: the scenario.
APPLY: dict[str, Callable[[Scenario, float], Scenario]] = {
    "train.mass_t": lambda s, v: replace(s, train=replace(s.train, mass_kg=tonne_to_kg(v))),
    "train.davis_scale": _scale_davis,
    "brake.delay_s": _delay,
    "brake.lag_s": _brake_field("lag_s"),
    "brake.air_lag_s": _brake_field("air_lag_s"),
    "brake.electric_lag_s": _brake_field("electric_lag_s"),
    "brake.gain": _set("brake_gain"),
    "disturbance.constant_kn": lambda s, v: replace(
        s, disturbance=replace(s.disturbance, constant_n=v * 1e3)
    ),
    "initial_speed_kmh": _set("initial_speed_mps", kmh_to_mps),
    "realism.wheel_scale_error": lambda s, v: replace(
        s, realism=replace(s.realism, wheel_scale_error=v)
    ),
    "realism.adhesion": lambda s, v: replace(s, realism=replace(s.realism, adhesion=v)),
}
assert set(APPLY) == set(VARIABLE_PARAMETERS), "every variable parameter needs an APPLY"


def check_spec(scenario: Scenario, spec: MonteCarloSpec) -> None:
    """Raise ConfigError now if a sampled parameter cannot apply to ``scenario``."""
    nominal = freeze_ato(scenario)
    for dist in spec.vary:
        for value in (dist.low, dist.high):
            if np.isfinite(value):
                _variant(nominal, {dist.key: value}, 0)


def freeze_ato(scenario: Scenario) -> Scenario:
    """The scenario with the ATO's model fixed to the nominal plant's values.

    In a sweep the plant varies and the ATO must not follow it: its resistance model
    and brake lead are pinned to the nominal ones (the load-weighed mass still follows
    the true mass: load weighing measures it).
    """
    t = scenario.train
    davis = scenario.ato.davis or (t.davis_a0, t.davis_a1, t.davis_a2)
    delay, lag = ato_brake_model(scenario)
    return replace(
        scenario,
        ato=replace(scenario.ato, davis=davis, brake_delay_s=delay, brake_lag_s=lag),
    )


def replay_scenario(scenario: Scenario, spec: MonteCarloSpec, run: int) -> Scenario:
    """The exact scenario of run ``run`` of a sweep, to simulate and plot it alone."""
    if not 0 <= run < spec.runs:
        raise ConfigError("run", run, f"a run index in [0, {spec.runs})")
    values, seeds = spec.samples()
    variant = _variant(
        freeze_ato(scenario), {k: float(v[run]) for k, v in values.items()}, int(seeds[run])
    )
    return variant


def _variant(nominal: Scenario, values: dict[str, float], seed: int) -> Scenario:
    s = replace(
        nominal,
        disturbance=replace(nominal.disturbance, seed=seed),
        realism=replace(nominal.realism, seed=seed + 1),
    )
    for key, value in values.items():
        try:
            s = APPLY[key](s, value)
        except ConfigError as exc:
            raise ConfigError(f"montecarlo.vary.{key}", value, exc.allowed) from exc
    return s


@njit(nogil=True, cache=True)
def run_batch_kernel(
    batch: RunInputs,
    ctrl_step: Any,
    brake_step: Any,
    metrics: np.ndarray,
    start: int,
    stop: int,
) -> None:
    """:func:`engine.run_kernel` for runs ``start..stop`` of ``batch`` (sim/layout.py).

    Run ``i`` gets exactly :func:`~railpilot.sim.layout.batch_row` ``(batch, i)``: the
    description a single run of its scenario gets. It releases the GIL, so
    :func:`run_batch` runs slices of a batch on several threads at once.
    """
    empty = np.zeros((0, engine.N_CHANNELS))
    for i in range(start, stop):
        row = batch_row(batch, i)
        engine.run_kernel(
            row,
            ctrl_step,
            brake_step,
            empty,
            1,
            metrics[i],
            engine.fresh_state(row),
            row.sim.n_steps,
        )


engine.keep_going_if_the_cache_cannot_save(run_batch_kernel)


def run_batch(
    batch: RunInputs, binding: Binding, brake_step: Any, threads: int | None = None
) -> np.ndarray:
    """Metrics of every run of ``batch``: in parallel threads for a compiled controller,
    one after another (each from a reset) for a Python one."""
    runs = int(batch.train.p.shape[0])
    metrics = np.zeros((runs, engine.N_METRICS))
    if not binding.parallel_safe:
        empty = np.zeros((0, engine.N_CHANNELS))
        for i in range(runs):
            row = batch_row(batch, i)
            with binding:
                engine.run_kernel(
                    row,
                    binding.step,
                    brake_step,
                    empty,
                    1,
                    metrics[i],
                    engine.fresh_state(row),
                    row.sim.n_steps,
                )
        return metrics
    n = max(1, min(threads or os.cpu_count() or 1, runs))
    bounds = np.linspace(0, runs, n + 1).astype(int)
    if n == 1:
        run_batch_kernel(batch, binding.step, brake_step, metrics, 0, runs)
        check_commands(binding, metrics, _state_at_failure(batch, binding, brake_step))
        return metrics
    # compile (or load) once before the threads race to do it
    run_batch_kernel(batch, binding.step, brake_step, metrics, 0, 0)
    with ThreadPoolExecutor(max_workers=n) as pool:
        jobs = [
            pool.submit(run_batch_kernel, batch, binding.step, brake_step, metrics, int(a), int(b))
            for a, b in itertools.pairwise(bounds)
        ]
        for job in jobs:
            job.result()
    check_commands(binding, metrics, _state_at_failure(batch, binding, brake_step))
    return metrics


def _state_at_failure(
    batch: RunInputs, binding: Binding, brake_step: Any
) -> Callable[[int], RunState]:
    """Run ``i``'s state where the loop stopped it, for an error (sim/run.py
    ``check_commands``): the batch keeps no run's state, so that run is run again alone,
    the same run to the bit (a run depends only on its row)."""

    def state_of(i: int) -> RunState:
        return run_from_start(batch_row(batch, i), binding, brake_step)[1]

    return state_of


def _chunk_inputs(
    nominal: Scenario,
    binding: Binding,
    reference: ReferenceIn,
    values: dict[str, np.ndarray],
    seeds: np.ndarray,
    start: int,
    stop: int,
) -> RunInputs:
    """The batch of runs ``start..stop``: built for all runs at once
    (:func:`~railpilot.sim.inputs.batch_inputs`), or run by run where that cannot be
    done (:func:`_chunk_inputs_per_run`); both give the same arrays."""
    line = line_inputs(nominal)  # no sampled parameter changes the line
    batch = batch_inputs(
        nominal,
        binding,
        {k: v[start:stop] for k, v in values.items()},
        seeds[start:stop],
        reference=reference,
        line=line,
    )
    if batch is not None:
        return batch
    return _chunk_inputs_per_run(nominal, binding, reference, values, seeds, start, stop, line)


def _chunk_inputs_per_run(
    nominal: Scenario,
    binding: Binding,
    reference: ReferenceIn,
    values: dict[str, np.ndarray],
    seeds: np.ndarray,
    start: int,
    stop: int,
    line: LineIn | None = None,
) -> RunInputs:
    """The batch of runs ``start..stop``: each run's own scenario and description, stacked.

    ``line``: the nominal scenario's line table, if built already (no sampled parameter
    changes the line).
    """
    line = line_inputs(nominal) if line is None else line
    return stack_runs(
        [
            run_inputs(
                _variant(nominal, {k: float(v[i]) for k, v in values.items()}, int(seeds[i])),
                binding,
                reference=reference,
                line=line,
            )
            for i in range(start, stop)
        ]
    )


def run_chunk(
    scenario: Scenario, controller_name: str, spec: MonteCarloSpec, start: int, stop: int
) -> np.ndarray:
    """Metrics ``(stop - start, N_METRICS)`` of runs ``start..stop``; runs anywhere.

    Pure function of its arguments (this is what a Dask worker executes).
    ``controller_name`` is a built-in's name (tuned once on the nominal plant) or a
    user's ``module:Name``.
    """
    nominal = freeze_ato(scenario)
    binding = bind(resolve_controller(nominal, controller_name))
    reference = reference_inputs(nominal)
    values, seeds = spec.samples()
    batch = _chunk_inputs(nominal, binding, reference, values, seeds, start, stop)
    return run_batch(batch, binding, brake_entry_of(nominal.brake).step)


@dataclass
class MonteCarloResult:
    """Per-run scalar metrics of a sweep and their statistics."""

    scenario: str
    controller: str
    spec: MonteCarloSpec
    metrics: np.ndarray  # (runs, N_METRICS)
    seeds: np.ndarray
    values: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def stop_errors(self) -> np.ndarray:
        return self.metrics[:, engine.M_STOP_ERR]

    def stats(self, tolerance_m: float = 0.30) -> dict[str, Any]:
        """Mean, std, percentiles of |stop error|, share within tolerance, worst run."""
        err = self.stop_errors
        stopped = np.isfinite(err)
        abs_err = np.where(stopped, np.abs(err), np.inf)
        worst = int(np.argmax(abs_err))
        finite = np.abs(err[stopped])
        jerk = self.metrics[:, engine.M_MAX_JERK]

        def pct(q: float) -> float | None:
            return float(np.percentile(finite, q)) if finite.size else None

        return {
            "runs": len(err),
            "not_stopped": int((~stopped).sum()),
            "mean_stop_error_m": float(np.mean(err[stopped])) if finite.size else None,
            "std_stop_error_m": float(np.std(err[stopped])) if finite.size else None,
            "p50_abs_stop_error_m": pct(50),
            "p95_abs_stop_error_m": pct(95),
            "p99_abs_stop_error_m": pct(99),
            "max_abs_stop_error_m": float(abs_err.max()) if stopped.all() else None,
            f"share_within_{tolerance_m:.2f}_m".replace(".", "_"): float(
                np.mean(abs_err <= tolerance_m)
            ),
            "max_jerk_mps3": float(jerk.max()),
            "p99_max_jerk_mps3": float(np.percentile(jerk, 99)),
            "max_speed_error_mps": float(self.metrics[:, engine.M_MAX_VERR].max()),
            "worst_run": worst,
            "worst_run_seed": int(self.seeds[worst]),
            "worst_run_values": {k: float(v[worst]) for k, v in self.values.items()},
            "worst_run_metrics": metrics_dict(self.metrics[worst]),
        }


#: Most per-step values one chunk's inputs may hold (runs x steps): a random disturbance
#: force is drawn for every step of every run of a chunk before it runs (8 bytes each),
#: so a long run shrinks the chunk to keep that table within about 400 MB. The examples'
#: chunks (500 runs of at most 24,000 steps, 1.2e7 values) are far below; a day-long
#: run at the finest step (1e7 steps) runs 5 at a time. The numbers do not depend on
#: the chunk: every run is the run it would be alone.
MAX_CHUNK_STEPS = 50_000_000


def _chunks(spec: MonteCarloSpec, n_steps: int) -> Iterator[tuple[int, int]]:
    """The runs of each chunk: ``spec.chunk`` at a time, fewer where the runs are so
    long that a chunk's per-step inputs would pass :data:`MAX_CHUNK_STEPS`."""
    size = max(1, min(spec.chunk, MAX_CHUNK_STEPS // max(n_steps, 1)))
    for start in range(0, spec.runs, size):
        yield start, min(start + size, spec.runs)


def run_montecarlo(
    scenario: Scenario,
    controller_name: str,
    spec: MonteCarloSpec,
    *,
    progress: bool = True,
    scheduler: str | None = None,
) -> MonteCarloResult:
    """Run the sweep locally (all cores) or on the Dask cluster at ``scheduler``."""
    values, seeds = spec.samples()
    check_spec(scenario, spec)  # a key that cannot apply fails now, not in a worker
    metrics = np.zeros((spec.runs, engine.N_METRICS))
    chunks = list(_chunks(spec, scenario.sim.n_steps))
    bar = _progress(len(chunks), spec.runs, progress)
    if scheduler is None:
        for start, stop in chunks:
            metrics[start:stop] = run_chunk(scenario, controller_name, spec, start, stop)
            bar(stop - start)
    else:
        from dask.distributed import as_completed

        from railpilot.cluster import dask_client

        with dask_client(scheduler) as client:
            futures = {
                client.submit(
                    run_chunk, scenario, controller_name, spec, start, stop, pure=False
                ): (start, stop)
                for start, stop in chunks
            }
            for future in as_completed(futures):
                start, stop = futures[future]
                metrics[start:stop] = future.result()
                bar(stop - start)
    bar(0, close=True)
    return MonteCarloResult(scenario.name, controller_name, spec, metrics, seeds, values)


def _progress(n_chunks: int, runs: int, enabled: bool) -> Callable[..., None]:
    """A tqdm bar on stderr (only when stderr is a terminal and progress is wanted)."""
    if not enabled or not sys.stderr.isatty():
        return lambda n, close=False: None
    from tqdm import tqdm

    bar = tqdm(total=runs, unit="run", file=sys.stderr)

    def update(n: int, close: bool = False) -> None:
        bar.update(n)
        if close:
            bar.close()

    return update
