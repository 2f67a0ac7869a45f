"""The dashboard's demo ground: the real ground over the simulated radio, with scripted trains.

:class:`DemoGround` is a :class:`~railpilot.web.source.DashboardSource` for the tests and
the demo. The ground is the co-simulation's (:class:`~railpilot.cosim.link_sim.LinkSim`):
the one :class:`~railpilot.ground.host.GroundHost` with its dispatch core, its train
records and the link's endpoints, exactly as ``ground serve`` runs them; the page reads it
through the live ground's own :class:`~railpilot.web.ground_source.ServerSource`. Only the
trains are made up: each one's onboard unit is the real link endpoint, and the train
obeys what it confirmed (its TSRs, its target point) with simple kinematics. There is no
wall clock inside: time moves when :meth:`DemoGround.advance` is called.

What happens on the line (all from the seed, the same every run):

- ``n_trains`` trains (default 24), loaded ones going UP to the line's end and empty ones
  going DOWN to its start, spread along the line;
- a train speeds up towards its cruising speed (its static limit less 5 km/h, looking 2 km
  ahead) and brakes for the TSRs and the target point its onboard confirmed;
- each train's radio is slow by its own seeded delay, so its acknowledgements come back 1
  to 5 s after a delivery (a scripted onboard answering late, as over a slow radio);
- the third UP train runs 10 km/h above its cruising speed (an ``overspeed`` alarm); the
  fourth DOWN train loses its radio 40 s before the start (a ``link`` alarm; it stops, as
  an onboard does on link loss, and what is sent to it waits for it);
- one TSR (track work, km 120-126.5) is in force from before the start; a section fault
  is declared on an UP block two blocks ahead of the UP train nearest the line's middle
  320 s before the start (cleared 20 minutes after it), and that train is told by
  a dispatch command.

Run the dashboard over it (``python -m railpilot.cosim.demo_ground --port 8080``).
"""

from __future__ import annotations

import argparse
import asyncio
import bisect
import contextlib
import math
import random
import secrets
import sys
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from railpilot.errors import ConfigError
from railpilot.ground.assembly import GroundParts
from railpilot.ground.dispatch import GroundDispatch
from railpilot.ground.host import refuse_keyless
from railpilot.ground.operations import OperationError, parse_operation
from railpilot.ground.targets import is_clear
from railpilot.ground.tsr_warning import refuse_unconfirmed
from railpilot.line.loader import load_line
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link import (
    Event,
    GroundConfig,
    LinkFailed,
    LinkTimers,
    OnboardConfig,
    Registered,
    TargetPointReceived,
    TrainRecord,
    TravelDirection,
    TsrApplied,
    TsrCancelled,
    TsrState,
)
from railpilot.link.events import AppliedTsr
from railpilot.link.keys import seeded_test_keys
from railpilot.units import kmh_to_mps
from railpilot.web.ground_source import ServerSource

from .channel import ChannelModel, Outage
from .link_sim import LinkSim, SimTrain

#: The demo ground's clock at the start: 2026-03-02 06:00:00 UTC [s since the epoch].
DEFAULT_START_S = 1_772_431_200.0
#: Simulated history before the start [s], so the time-distance graph has a past.
WARMUP_S = 600.0
#: The shortest warm-up [s]: the trains register, then the preset TSR is set and the
#: section fault declared before the start (the tests' grounds, cheap to build).
MIN_WARMUP_S = 330.0
#: When the preset TSR is set and the section fault declared, before the start [s].
PRESET_TSR_BEFORE_S = 325.0
FAULT_BEFORE_S = 320.0
#: Cruising margin below the static limit [km/h], the overspeeding train's excess [km/h].
CRUISE_MARGIN_KMH = 5.0
OVERSPEED_KMH = 10.0
#: Acceleration and service braking of the made-up trains [m/s^2], how far they look
#: ahead for a lower limit [m], where they stop before a target point [m], their step [s].
ACCEL_MPS2 = 0.15
BRAKE_MPS2 = 0.35
LOOKAHEAD_M = 2000.0
TARGET_MARGIN_M = 150.0
STEP_S = 1.0
#: The link's timers on the demo's slow radio: a round trip of up to 5 s is normal there,
#: so a frame may be that old, a resend waits longer, and a timeout takes 8 cycles.
DEMO_TIMERS = LinkTimers(timeout_cycles=8, resend_interval_s=6.0, max_round_trip_s=8.0)


@dataclass
class ScriptedTrain:
    """One made-up train (a :class:`~railpilot.net.client.Mover`): it obeys what its
    onboard confirmed; the ground sees only what the onboard reports."""

    line: RailLine
    limits: tuple[list[float], list[float]]  # its static limit: edges [m], values [m/s]
    direction: TravelDirection
    head_m: float
    destination_m: float
    excess_mps: float = 0.0
    speed_mps: float = 0.0
    elapsed_s: float = 0.0
    link_up: bool = True
    arrived: bool = False
    tsrs: dict[int, AppliedTsr] = field(default_factory=dict)
    target_m: float | None = None

    @property
    def sign(self) -> float:
        return 1.0 if self.direction is UP else -1.0

    def state(self, elapsed_s: float) -> tuple[float, float]:
        """``(position_m, speed_mps)`` at ``elapsed_s``: moved on in steps of at most
        :data:`STEP_S` (the simulation asks in time order)."""
        while self.elapsed_s < elapsed_s - 1e-9:
            self._step(min(STEP_S, elapsed_s - self.elapsed_s))
        return self.head_m, self.speed_mps

    def on_event(self, event: Event, now_s: float) -> None:
        """What the onboard tells its driver."""
        if isinstance(event, TsrApplied):
            self.tsrs[event.tsr.session] = event.tsr
        elif isinstance(event, TsrCancelled):
            self.tsrs.pop(event.session, None)
        elif isinstance(event, TargetPointReceived):
            clear = is_clear(event.target, self.line)
            self.target_m = None if clear else event.target.position_m
        elif isinstance(event, LinkFailed):
            self.link_up = False  # an onboard stops on link loss
        elif isinstance(event, Registered):
            self.link_up = True

    def _step(self, dt_s: float) -> None:
        self.elapsed_s += dt_s
        if self.arrived:
            return
        wanted = self._wanted_mps() if self.link_up else 0.0
        if self.speed_mps < wanted:
            self.speed_mps = min(wanted, self.speed_mps + ACCEL_MPS2 * dt_s)
        else:
            self.speed_mps = max(wanted, self.speed_mps - BRAKE_MPS2 * dt_s)
        head = self.head_m + self.sign * self.speed_mps * dt_s
        if self.sign * (head - self.destination_m) >= 0:
            head, self.speed_mps, self.arrived = self.destination_m, 0.0, True
        self.head_m = head

    def cruise_mps(self) -> float:
        """Its static limit, the lowest within :data:`LOOKAHEAD_M`, less the margin [m/s]."""
        edges, values = self.limits
        lowest = math.inf
        for ahead in (0.0, 0.25 * LOOKAHEAD_M, 0.5 * LOOKAHEAD_M, LOOKAHEAD_M):
            x = min(max(self.head_m + self.sign * ahead, edges[0]), edges[-1])
            i = min(max(bisect.bisect_right(edges, x) - 1, 0), len(values) - 1)
            lowest = min(lowest, values[i])
        return lowest - kmh_to_mps(CRUISE_MARGIN_KMH)

    def _wanted_mps(self) -> float:
        wanted = self.cruise_mps()
        ahead = self.head_m + self.sign * LOOKAHEAD_M
        low, high = sorted((self.head_m, ahead))
        for tsr in self.tsrs.values():
            if tsr.zone_start_m <= high and tsr.zone_end_m >= low:
                wanted = min(wanted, tsr.limit_mps - kmh_to_mps(2.0))
        if self.target_m is not None:
            distance = self.sign * (self.target_m - self.head_m) - TARGET_MARGIN_M
            wanted = min(wanted, math.sqrt(2.0 * BRAKE_MPS2 * max(distance, 0.0)))
        return max(wanted + self.excess_mps, 0.0)


class _SimServer:
    """What the live source reads of a ground server, over the simulation."""

    def __init__(self, sim: LinkSim) -> None:
        self.sim = sim

    @property
    def records(self) -> dict[int, TrainRecord]:
        return self.sim.records

    def clock(self) -> float:
        return self.sim.now_s


class _SimDispatchHost:
    """The simulated ground as the live source sees a dispatch host: its forms go through
    the host's :meth:`~railpilot.ground.host.GroundHost.operate`, as the live ground's."""

    restored = True

    def __init__(self, sim: LinkSim) -> None:
        self.sim = sim
        self.server = _SimServer(sim)
        self.line = sim.line
        self.tick_s = sim.tick_s

    @property
    def dispatch(self) -> GroundDispatch:
        return self.sim.dispatch

    def sync(self) -> None:
        self.sim.host.sync(t for t, c in self.sim.live.items() if c.open)

    def execute_now(
        self, op: str, fields: Mapping[str, Any], actor: str, *, confirm: bool = False
    ) -> dict[str, Any]:
        now = self.sim.now_s
        operation = parse_operation(op, fields, line=self.line, now_s=now)
        refuse_keyless(operation, self.sim.keys, "")  # as the live ground
        registry = self.sim.dispatch.registry
        refuse_unconfirmed(
            operation, registry.reports(), now, validity_s=registry.validity_s, confirm=confirm
        )
        return dict(self.sim.operate(operation, actor).result)


class DemoGround:
    """The demo line (module docstring); thread-safe.

    Parameters
    ----------
    n_trains
        How many trains (2 to 200), half of them each way.
    seed
        Everything made up (delays, lengths) comes from it.
    line
        The line (default: the shipped heavy-haul line); its first train category runs
        UP, its last DOWN, and the preset TSR lies at km 120-126.5.
    start_s
        The ground clock [s] after the warm-up, when the page first looks.
    warmup_s
        How long the line runs before the start [s] (at least 330: the preset TSR, the
        section fault and the link loss happen in its last 325 s).
    off_radio
        Trains (of ids 1001 on) whose onboard unit stays off: they run on the line, and
        the ground never hears of them.
    """

    def __init__(
        self,
        n_trains: int = 24,
        *,
        seed: int = 0,
        line: RailLine | None = None,
        start_s: float = DEFAULT_START_S,
        warmup_s: float = WARMUP_S,
        off_radio: tuple[int, ...] = (),
    ) -> None:
        if type(n_trains) is not int or not 2 <= n_trains <= 200:
            raise ConfigError("n_trains", n_trains, "an integer from 2 to 200")
        unknown = [t for t in off_radio if not 1001 <= t < 1001 + n_trains]
        if unknown:
            raise ConfigError("off_radio", unknown, f"ids of the trains, 1001-{1000 + n_trains}")
        self.off_radio = frozenset(off_radio)
        if not (isinstance(warmup_s, int | float) and MIN_WARMUP_S <= warmup_s <= 7200.0):
            raise ConfigError("warmup_s", warmup_s, f"a time from {MIN_WARMUP_S:g} to 7200 [s]")
        self.line = line if line is not None else load_line("heavy-haul")
        self._lock = threading.RLock()
        self._version = 0
        self.warmup_s = float(warmup_s)
        rng = random.Random(seed)
        self.movers: dict[int, ScriptedTrain] = {}
        sim_trains, channels = self._make_trains(n_trains, rng)
        ids = sorted(self.movers)
        parts = GroundParts(
            GroundConfig(ground_id=1, timers=DEMO_TIMERS), self.line, seeded_test_keys(seed, ids)
        )
        self.sim = LinkSim.over(
            parts, sim_trains, channels, seed=seed, start_s=float(start_s) - self.warmup_s
        )
        self.source = ServerSource(_SimDispatchHost(self.sim))
        #: the train told of the section fault (set when it is declared)
        self.faulted: int | None = None
        self.sim.call_at(self.warmup_s - PRESET_TSR_BEFORE_S, self._preset_tsr)
        self.sim.call_at(self.warmup_s - FAULT_BEFORE_S, self._declare_fault)
        self.sim.call_at(self.warmup_s + 1200.0, self._clear_fault)
        self._run_to(self.warmup_s)

    def __getstate__(self) -> dict[str, Any]:
        # copy.deepcopy of a warmed-up ground (the tests copy one instead of building one
        # each): the copy gets a lock of its own
        state = self.__dict__.copy()
        del state["_lock"]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.RLock()

    # ------------------------------------------------------------------ set-up

    def _make_trains(
        self, n_trains: int, rng: random.Random
    ) -> tuple[list[SimTrain], dict[int, ChannelModel]]:
        line = self.line
        category = {UP: line.categories[0], DOWN: line.categories[-1]}
        limits = {}
        for travel, name in category.items():
            edges, values = line.static_limit(name, travel)
            limits[travel] = (edges.tolist(), values.tolist())
        n_up = (n_trains + 1) // 2
        sim_trains: list[SimTrain] = []
        channels: dict[int, ChannelModel] = {}
        #: the scripted incidents' trains (None: too few trains for it)
        self.overspeeding: int | None = None
        self.link_lost: int | None = None
        for k in range(n_trains):
            travel = UP if k < n_up else DOWN
            index = k if travel is UP else k - n_up
            count = n_up if travel is UP else n_trains - n_up
            length = 2650.0 if rng.random() < 0.6 else 1350.0
            # heads spread evenly at the start, stepped back over the warm-up
            along = (index + 0.5) / count * (line.length_m - 6000.0) + 3000.0
            mover = ScriptedTrain(line, limits[travel], travel, 0.0, 0.0)
            mover.head_m = line.start_m + along if travel is UP else line.end_m - along
            along = max(along - 0.9 * mover.cruise_mps() * self.warmup_s, length + 500.0)
            mover.head_m = line.start_m + along if travel is UP else line.end_m - along
            mover.speed_mps = mover.cruise_mps()
            last = line.stations[-1] if travel is UP else line.stations[0]
            mover.destination_m = last.stop_m(travel)
            train_id = 1001 + k
            if travel is UP and index == 2:
                mover.excess_mps = kmh_to_mps(OVERSPEED_KMH)
                self.overspeeding = train_id
            delay_s = 1.0 + (train_id * 7) % 5  # its acknowledgements' round trip [s]
            outages: tuple[Outage, ...] = ()
            if travel is DOWN and index == 3:
                self.link_lost = train_id
                outages = (Outage(self.warmup_s - 40.0, 1e9),)
            channels[train_id] = ChannelModel(
                latency_min_s=delay_s / 2,
                latency_median_s=delay_s / 2,
                latency_sigma=0.0,
                outages=outages,
            )
            config = OnboardConfig(
                train_id=train_id,
                ground_id=1,
                train_number=str(76001 + 2 * index + (0 if travel is UP else 1)),
                loco_number=f"HXD{train_id}",
                driver_id=7000 + train_id,
                train_length_m=length,
                timers=DEMO_TIMERS,
            )
            self.movers[train_id] = mover
            # an onboard that stays off: it would come up long after any run ends
            power_on_s = math.inf if train_id in self.off_radio else 0.0
            sim_trains.append(SimTrain(config, mover, power_on_s, on_event=mover.on_event))
        return sim_trains, channels

    def _preset_tsr(self) -> None:
        fields = {
            "start_km": 120.0,
            "end_km": 126.5,
            "limit_kmh": 45,
            "valid_from_min": 0,
            "valid_until_min": 240,
            "reason": "track work: rail renewal",
        }
        self._operate("tsr_set", fields, "dispatcher D. Wang")

    def _declare_fault(self) -> None:
        middle = 0.5 * (self.line.start_m + self.line.end_m)
        ups = [
            (i, m)
            for i, m in self.movers.items()
            if m.direction is UP and m.link_up and i not in self.off_radio
        ]
        train_id, mover = min(ups, key=lambda im: abs(im[1].head_m - middle))
        sections = self.line.block_sections_for(UP)
        here = self.line.block_section_at(mover.head_m, UP)
        block = sections[min(sections.index(here) + 2, len(sections) - 1)]
        self._operate(
            "restriction_set", {"reason": "section_fault", "block": block.id}, "dispatcher"
        )
        signal = block.entry_signal or "the line's end"
        text = f"Section fault in block {block.id}: stop at signal {signal}, wait."
        self._operate("dispatch", {"trains": str(train_id), "text": text}, "dispatcher")
        self.faulted = train_id

    def _clear_fault(self) -> None:
        for ident in sorted(self.sim.dispatch.restrictions):
            self._operate("restriction_clear", {"id": ident}, "dispatcher")

    def _operate(self, op: str, fields: Mapping[str, Any], actor: str) -> None:
        operation = parse_operation(op, fields, line=self.line, now_s=self.sim.now_s)
        self.sim.operate(operation, actor)

    def _run_to(self, t_s: float) -> None:
        """Run the line to ``t_s`` after the warm-up's start; arrived trains leave it."""
        self.sim.run_until(t_s)
        for train_id, mover in self.movers.items():
            if mover.arrived and train_id not in self.sim.retiring:
                self.sim.retire(train_id)

    # ------------------------------------------------------------------ the clock

    def advance(self, dt_s: float) -> None:
        """Let ``dt_s`` [s] of ground time pass."""
        if not (isinstance(dt_s, int | float) and math.isfinite(dt_s) and dt_s >= 0):
            raise ConfigError("dt_s", dt_s, "a finite time >= 0 [s]")
        with self._lock:
            self._run_to(self.sim.now_s - self.sim.start_s + float(dt_s))
            self._version += 1

    def now_s(self) -> float:
        with self._lock:
            return self.sim.now_s

    def version(self) -> int:
        with self._lock:
            return self._version

    # ------------------------------------------------------------------ DashboardSource

    def snapshot(self, now_s: float) -> dict[str, Any]:
        """The page's picture (the live source's) at the ground's clock."""
        with self._lock:
            snap = self.source.snapshot(max(float(now_s), self.sim.now_s))
            snap["version"] = self._version
            return snap

    def _form(self, call: Callable[[], dict[str, Any]]) -> dict[str, Any]:
        with self._lock:
            try:
                result = call()
            except OperationError as exc:
                return {"errors": exc.errors}
            if "ok" in result:
                self._version += 1
            return result

    def set_tsr(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        return self._form(lambda: self.source.set_tsr(fields, actor, now_s))

    def cancel_tsr(self, session: int, actor: str, now_s: float) -> dict[str, Any]:
        return self._form(lambda: self.source.cancel_tsr(session, actor, now_s))

    def set_restriction(
        self, fields: Mapping[str, Any], actor: str, now_s: float
    ) -> dict[str, Any]:
        return self._form(lambda: self.source.set_restriction(fields, actor, now_s))

    def clear_restriction(self, ident: int, actor: str, now_s: float) -> dict[str, Any]:
        return self._form(lambda: self.source.clear_restriction(ident, actor, now_s))

    def send_dispatch(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        return self._form(lambda: self.source.send_dispatch(fields, actor, now_s))

    # ------------------------------------------------------------------ for tests and tools

    def delivery_state(self, session: int, train_id: int) -> TsrState | None:
        """Where the delivery of TSR ``session`` to ``train_id`` stands (None: not sent)."""
        with self._lock:
            return self.source.delivery_state(session, train_id)

    def train_ids(self) -> tuple[int, ...]:
        """The made-up trains' ids, ascending."""
        return tuple(sorted(self.movers))


# ---------------------------------------------------------------------------- the demo


def main(argv: list[str] | None = None) -> int:
    """``python -m railpilot.cosim.demo_ground``: serve the dashboard over a :class:`DemoGround`."""
    import uvicorn

    from railpilot.web.app import DEFAULT_HOST, LOCAL_HOSTS, create_app, server_config

    parser = argparse.ArgumentParser(
        prog="python -m railpilot.cosim.demo_ground",
        description="Serve the dispatcher dashboard over a simulated heavy-haul line.",
    )
    parser.add_argument("--host", default=DEFAULT_HOST, help=f"address to bind [{DEFAULT_HOST}]")
    parser.add_argument("--port", type=int, default=8080, help="port (0: any free) [8080]")
    parser.add_argument("--trains", type=int, default=24, help="how many trains [24]")
    parser.add_argument("--seed", type=int, default=0, help="seed of everything made up [0]")
    parser.add_argument(
        "--speed", type=float, default=1.0, help="ground seconds per wall second [1]"
    )
    parser.add_argument("--token", default=None, help="dispatcher token [a random one]")
    args = parser.parse_args(argv)
    token = args.token or secrets.token_urlsafe(16)
    ground = DemoGround(args.trains, seed=args.seed)
    # Bound elsewhere on purpose, the page answers to any host name (the user's choice).
    hosts = LOCAL_HOSTS if args.host in LOCAL_HOSTS else None
    if hosts is None:
        print(
            f"warning: binding to {args.host}: anyone who can reach it sees the line "
            "(setting and cancelling TSRs still needs the token)",
            file=sys.stderr,
        )
    app = create_app(ground, token=token, allowed_hosts=hosts)
    server = uvicorn.Server(server_config(app, host=args.host, port=args.port))

    async def run() -> None:
        loop = asyncio.get_running_loop()
        serving = asyncio.create_task(server.serve())
        while not server.started and not serving.done():
            await asyncio.sleep(0.05)
        if server.started:
            port = server.servers[0].sockets[0].getsockname()[1]
            print(f"dashboard: http://{args.host}:{port}/", flush=True)
            print(f"dispatcher token: {token}", flush=True)
        last = loop.time()
        while not serving.done():
            await asyncio.sleep(0.5)
            now = loop.time()
            ground.advance(args.speed * (now - last))
            last = now
        await serving

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run())
    return 0


if __name__ == "__main__":
    sys.exit(main())
