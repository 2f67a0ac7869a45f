"""The consist: one description of a train as the vehicles it is made of, from the head.

A :class:`Consist` lists its :class:`Vehicle` objects (locomotives and wagons) from the
head, each with its own mass, rotating-mass factor, length over couplers, Davis resistance,
friction-brake force and distributor, and the draft gear that joins it to the next vehicle.
Everything a simulation needs follows from it:

* per-vehicle arrays (masses, lengths, positions, Davis coefficients, brake forces) for the
  longitudinal (multi-mass) dynamics and the brake pipe along the train;
* :meth:`Consist.point_mass_train`, the same train as one point mass
  (:class:`~railpilot.vehicle.train.Train`), so the point-mass and the multi-mass models run
  the same train.

Three presets are shipped (:data:`CONSIST_PRESETS`), consist files in
``railpilot/vehicle/data/consists/``; :mod:`railpilot.scenario.consist_file` reads those
(``consist_preset``) and a user's own. docs/consist.md gives every number with its source.

SI units inside: kg, m, N, s; Davis coefficients are specific resistances [N/kN] of the
vehicle's own weight with the speed in km/h, as TB/T 1407 (the Chinese traction
calculation rules) and the rest of railpilot write them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.traction import Locomotive
from railpilot.vehicle.train import MAX_LENGTH_M, ElectricBrakeCurve, Train

#: the kinds of vehicle
KINDS = ("locomotive", "wagon")
#: the distributor (control valve) types: a freight distributor releases fully on any rise
#: of the brake-pipe pressure (Chinese 120 / 120-1, AAR ABD/ABDX); a UIC passenger
#: distributor releases in steps; "none": no air brake on this vehicle (or cut out)
DISTRIBUTORS = ("direct-release", "graduated-release", "none")

#: Heaviest vehicle [kg]: far above any rail vehicle (the heaviest locomotives and wagons
#: are 200-300 t; two-section locomotives up to about 300 t)
MAX_VEHICLE_MASS_KG = 1_000e3
#: Longest vehicle over couplers [m] (an articulated unit or a locomotive of two or three
#: sections is about 35-60 m)
MAX_VEHICLE_LENGTH_M = 100.0
#: Largest rotating-mass factor gamma [-] (a light vehicle with heavy drives is about 0.3)
MAX_ROTATING_MASS_FACTOR = 5.0
#: Largest Davis coefficient [N/kN, v in km/h] (real ones are a few N/kN, 1e-2, 1e-3)
MAX_DAVIS = 100.0
#: Largest friction-brake force of one vehicle [N]: its weight times an adhesion of 1
MAX_BRAKE_FORCE_N = MAX_VEHICLE_MASS_KG * 9.81
#: Brake-pipe pressure range [kPa, gauge]: UIC 500 kPa, Chinese heavy haul 600 kPa,
#: AAR 90-110 psi (620-760 kPa)
MAX_BRAKE_PIPE_KPA = 1_000.0
#: Longest radio delay of a distributed-power command [s] (a lost message is retried in
#: about a second; past this the remote is out of contact, which is not modelled)
MAX_DP_DELAY_S = 60.0

#: Charged brake-pipe pressure [kPa, gauge] of a consist that gives none. ASSUMED: 600 kPa,
#: the pressure commonly reported for Chinese heavy-haul trains (500 kPa is the UIC and the
#: ordinary Chinese freight value); not found in a source read through the search tool
#: (docs/consist.md).
BRAKE_PIPE_KPA = 600.0
#: Delay [s] of the lead's commands at a distributed-power remote. ASSUMED: 1.5 s, within
#: the 1-2 s usually quoted for radio (LOCOTROL-type) distributed power; no published
#: figure found (docs/consist.md).
DP_RADIO_DELAY_S = 1.5

#: the shipped consists: name -> file in railpilot/vehicle/data/consists/
PRESET_FILES: dict[str, str] = {
    "heavy-haul-10kt": "heavy_haul_10kt.toml",
    "heavy-haul-10kt-empty": "heavy_haul_10kt_empty.toml",
    "heavy-haul-20kt-dp": "heavy_haul_20kt_dp.toml",
}
CONSIST_PRESETS: tuple[str, ...] = tuple(PRESET_FILES)


def _bounded(
    name: str, value: object, *, positive: bool = False, maximum: float, unit: str
) -> float:
    return check_number(
        name,
        value,
        minimum=None if positive else 0.0,
        positive=positive,
        maximum=maximum,
        unit=unit,
        error=ConfigError,
    )


@dataclass(frozen=True)
class Vehicle:
    """One vehicle of a consist, as it runs in it.

    Attributes
    ----------
    name
        Unique in the consist, e.g. ``"HXD1-1"``, ``"C80-037"``.
    kind
        ``"locomotive"`` or ``"wagon"``.
    mass_kg
        Mass [kg] as it runs in this consist (loaded or tare).
    rotating_mass_factor
        ``gamma`` [-]: its effective mass is ``mass_kg (1 + gamma)``.
    length_m
        Length over couplers [m].
    davis_a0, davis_a1, davis_a2
        Basic resistance ``w = a0 + a1 V + a2 V^2`` [N/kN of its own weight], ``V`` in km/h.
    service_brake_force_n
        Friction (air) brake force at the rail [N] at full-service brake-cylinder pressure.
    distributor
        ``"direct-release"`` (Chinese 120, AAR), ``"graduated-release"`` (UIC passenger) or
        ``"none"`` (no air brake: then the brake force must be 0).
    draft_gear
        The connection at its rear, to the next vehicle (the last vehicle's is unused).
    locomotive
        Traction and regenerative envelopes: locomotives only (None for a wagon).
    remote
        A distributed-power remote unit (a locomotive that is not the lead).
    """

    name: str
    kind: str
    mass_kg: float
    rotating_mass_factor: float
    length_m: float
    davis_a0: float
    davis_a1: float
    davis_a2: float
    service_brake_force_n: float
    distributor: str
    draft_gear: DraftGear
    locomotive: Locomotive | None = None
    remote: bool = False

    def __post_init__(self) -> None:
        where = f"vehicle[{self.name!r}]" if isinstance(self.name, str) else "vehicle"
        if not isinstance(self.name, str) or not self.name:
            raise ConfigError(f"{where}.name", self.name, "a non-empty string")
        if not (isinstance(self.kind, str) and self.kind in KINDS):
            raise ConfigError(f"{where}.kind", self.kind, f"one of {', '.join(KINDS)}")
        _bounded(
            f"{where}.mass_kg", self.mass_kg, positive=True, maximum=MAX_VEHICLE_MASS_KG, unit="kg"
        )
        _bounded(
            f"{where}.rotating_mass_factor",
            self.rotating_mass_factor,
            maximum=MAX_ROTATING_MASS_FACTOR,
            unit="-",
        )
        _bounded(
            f"{where}.length_m",
            self.length_m,
            positive=True,
            maximum=MAX_VEHICLE_LENGTH_M,
            unit="m",
        )
        for name in ("davis_a0", "davis_a1", "davis_a2"):
            _bounded(f"{where}.{name}", getattr(self, name), maximum=MAX_DAVIS, unit="N/kN")
        _bounded(
            f"{where}.service_brake_force_n",
            self.service_brake_force_n,
            maximum=MAX_BRAKE_FORCE_N,
            unit="N",
        )
        if not (isinstance(self.distributor, str) and self.distributor in DISTRIBUTORS):
            raise ConfigError(
                f"{where}.distributor", self.distributor, f"one of {', '.join(DISTRIBUTORS)}"
            )
        if self.distributor == "none" and self.service_brake_force_n != 0:
            raise ConfigError(
                f"{where}.service_brake_force_n",
                self.service_brake_force_n,
                "0 N: the vehicle has no air brake (distributor 'none')",
            )
        if not isinstance(self.draft_gear, DraftGear):
            raise ConfigError(f"{where}.draft_gear", self.draft_gear, "a DraftGear")
        if self.kind == "locomotive" and not isinstance(self.locomotive, Locomotive):
            raise ConfigError(
                f"{where}.locomotive", self.locomotive, "a Locomotive (its envelopes)"
            )
        if self.kind == "wagon" and self.locomotive is not None:
            raise ConfigError(f"{where}.locomotive", self.locomotive, "None for a wagon")
        if not isinstance(self.remote, bool):  # a NumPy bool would stay one in the field
            raise ConfigError(f"{where}.remote", self.remote, "True or False")
        if self.remote and self.kind != "locomotive":
            raise ConfigError(f"{where}.remote", self.remote, "False: only a locomotive")

    @property
    def effective_mass_kg(self) -> float:
        """``m (1 + gamma)`` [kg]."""
        return self.mass_kg * (1.0 + self.rotating_mass_factor)


@dataclass(frozen=True)
class Consist:
    """A train as its vehicles, from the head, and the settings of its brake and radio.

    Attributes
    ----------
    name
        Name of the consist.
    vehicles
        The vehicles from the head; the first is the lead locomotive (not remote).
    brake_pipe_kpa
        Charged brake-pipe pressure [kPa, gauge].
    dp_radio_delay_s
        Delay [s] of the lead's commands at a remote unit (distributed power).

    Every array method returns a new NumPy array, one entry per vehicle unless it says.
    """

    name: str
    vehicles: tuple[Vehicle, ...]
    brake_pipe_kpa: float = BRAKE_PIPE_KPA
    dp_radio_delay_s: float = DP_RADIO_DELAY_S

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ConfigError("consist.name", self.name, "a non-empty string")
        vehicles = self.vehicles
        if not isinstance(vehicles, tuple) or not vehicles:
            raise ConfigError("consist.vehicles", vehicles, "a non-empty tuple of Vehicle")
        for i, vehicle in enumerate(vehicles):
            if not isinstance(vehicle, Vehicle):
                raise ConfigError(f"consist.vehicles[{i}]", vehicle, "a Vehicle")
        lead = vehicles[0]
        if lead.kind != "locomotive" or lead.remote:
            raise ConfigError(
                "consist.vehicles[0]",
                f"{lead.name} ({lead.kind}{', remote' if lead.remote else ''})",
                "the lead locomotive (a locomotive, not remote)",
            )
        seen: set[str] = set()
        for i, vehicle in enumerate(vehicles):
            if vehicle.name in seen:
                raise ConfigError(
                    f"consist.vehicles[{i}].name", vehicle.name, "a name unique in the consist"
                )
            seen.add(vehicle.name)
        length = float(sum(v.length_m for v in vehicles))
        if length > MAX_LENGTH_M:
            raise ConfigError(
                "consist.length_m",
                length,
                f"a train at most {MAX_LENGTH_M:g} m long (railpilot.vehicle.train.MAX_LENGTH_M)",
            )
        check_number(
            "consist.brake_pipe_kpa",
            self.brake_pipe_kpa,
            positive=True,
            maximum=MAX_BRAKE_PIPE_KPA,
            unit="kPa",
            error=ConfigError,
        )
        check_number(
            "consist.dp_radio_delay_s",
            self.dp_radio_delay_s,
            minimum=0.0,
            maximum=MAX_DP_DELAY_S,
            unit="s",
            error=ConfigError,
        )

    # --- totals ---------------------------------------------------------------------

    @property
    def n_vehicles(self) -> int:
        """Number of vehicles."""
        return len(self.vehicles)

    @property
    def mass_kg(self) -> float:
        """Total mass [kg]."""
        return float(self.masses_kg().sum())

    @property
    def length_m(self) -> float:
        """Total length over couplers [m]."""
        return float(self.lengths_m().sum())

    # --- per-vehicle arrays -----------------------------------------------------------

    def _array(self, field: str) -> np.ndarray:
        return np.array([getattr(v, field) for v in self.vehicles], dtype=float)

    def masses_kg(self) -> np.ndarray:
        """Mass of each vehicle [kg]."""
        return self._array("mass_kg")

    def rotating_mass_factors(self) -> np.ndarray:
        """``gamma`` of each vehicle [-]."""
        return self._array("rotating_mass_factor")

    def effective_masses_kg(self) -> np.ndarray:
        """``m (1 + gamma)`` of each vehicle [kg]."""
        return self.masses_kg() * (1.0 + self.rotating_mass_factors())

    def lengths_m(self) -> np.ndarray:
        """Length over couplers of each vehicle [m]."""
        return self._array("length_m")

    def davis(self) -> np.ndarray:
        """Davis coefficients, shape ``(n, 3)``: ``a0, a1, a2`` [N/kN, V in km/h]."""
        return np.array(
            [(v.davis_a0, v.davis_a1, v.davis_a2) for v in self.vehicles], dtype=float
        ).reshape(self.n_vehicles, 3)

    def service_brake_force_n(self) -> np.ndarray:
        """Full-service friction-brake force at the rail of each vehicle [N]."""
        return self._array("service_brake_force_n")

    def direct_release(self) -> np.ndarray:
        """True where the vehicle's distributor is direct-release (bool array)."""
        return np.array([v.distributor == "direct-release" for v in self.vehicles], dtype=bool)

    def has_air_brake(self) -> np.ndarray:
        """True where the vehicle has an air brake (a distributor other than "none")."""
        return np.array([v.distributor != "none" for v in self.vehicles], dtype=bool)

    def front_m(self) -> np.ndarray:
        """Distance [m] from the head of the train to each vehicle's front (0 for the
        first)."""
        lengths = self.lengths_m()
        front = np.zeros(self.n_vehicles)
        np.cumsum(lengths[:-1], out=front[1:])
        return front

    def locomotive_indices(self) -> np.ndarray:
        """Indices of the locomotives (int64, from the head: the lead first)."""
        return np.array(
            [i for i, v in enumerate(self.vehicles) if v.kind == "locomotive"], dtype=np.int64
        )

    def remote_indices(self) -> np.ndarray:
        """Indices of the distributed-power remote units (int64, from the head)."""
        return np.array([i for i, v in enumerate(self.vehicles) if v.remote], dtype=np.int64)

    def draft_gears(self) -> tuple[DraftGear, ...]:
        """The ``n - 1`` connections from the head: ``[i]`` joins vehicle ``i`` to ``i + 1``
        (each vehicle's own rear draft gear)."""
        return tuple(v.draft_gear for v in self.vehicles[:-1])

    # --- the same train as a point mass ----------------------------------------------

    def point_mass_train(self) -> Train:
        """The consist as one point mass (:class:`~railpilot.vehicle.train.Train`).

        Returns
        -------
        Train
            ``mass_kg = sum m_i``; ``length_m = sum L_i``;
            ``rotating_mass_factor = sum(m_i gamma_i) / sum m_i`` (the effective masses add);
            Davis ``a_k = sum(m_i a_k,i) / sum m_i`` for k = 0, 1, 2;
            ``max_service_decel_mps2 = sum F_B,i / sum m_i (1 + gamma_i)`` (every brake at
            full service, acting on the effective mass, as the brake models take ``a_max``);
            the electric brake is the locomotives' regenerative envelopes added
            (``sum F_E0``, ``sum P_E``; their low-speed fade is the locomotive model's, not
            the point mass's) shared by ``motor_cars`` = the number of locomotives.

        Notes
        -----
        The Davis average is exact, not an approximation: a specific resistance ``w_i``
        [N/kN] is a force ``w_i m_i g / 1000``, so the train's force is
        ``(sum m_i w_i) g / 1000`` and its specific resistance ``sum m_i w_i / sum m_i``,
        coefficient by coefficient. The point mass loses what depends on position: the
        in-train forces, and the line under the train (railpilot.vehicle.profile averages
        the line over the length instead).

        Raises
        ------
        ConfigError
            If no vehicle has a friction brake (a Train needs a service deceleration).
        """
        masses = self.masses_kg()
        total = float(masses.sum())
        effective = float(self.effective_masses_kg().sum())
        brake_n = float(self.service_brake_force_n().sum())
        if brake_n <= 0.0:
            raise ConfigError(
                f"consist[{self.name!r}].service_brake_force_n",
                brake_n,
                "a train with a friction brake on at least one vehicle (> 0 N in all)",
            )
        davis = masses @ self.davis() / total
        locomotives = [v.locomotive for v in self.vehicles if v.locomotive is not None]
        return Train(
            mass_kg=total,
            rotating_mass_factor=effective / total - 1.0,
            length_m=self.length_m,
            davis_a0=float(davis[0]),
            davis_a1=float(davis[1]),
            davis_a2=float(davis[2]),
            max_service_decel_mps2=brake_n / effective,
            electric_brake=ElectricBrakeCurve(
                max_force_n=float(sum(loco.regen.max_force_n for loco in locomotives)),
                max_power_w=float(sum(loco.regen.max_power_w for loco in locomotives)),
            ),
            motor_cars=len(locomotives),
        )


def describe(consist: Consist) -> dict[str, Any]:
    """A short summary of ``consist`` for a report or ``--json``: counts, totals in t and m,
    the locomotives' places and the point-mass figures."""
    kinds = [v.kind for v in consist.vehicles]
    summary: dict[str, Any] = {
        "name": consist.name,
        "vehicles": consist.n_vehicles,
        "locomotives": kinds.count("locomotive"),
        "wagons": kinds.count("wagon"),
        "mass_t": consist.mass_kg / 1000.0,
        "length_m": consist.length_m,
        "locomotive_indices": consist.locomotive_indices().tolist(),
        "remote_indices": consist.remote_indices().tolist(),
        "brake_pipe_kpa": consist.brake_pipe_kpa,
        "dp_radio_delay_s": consist.dp_radio_delay_s,
    }
    if float(consist.service_brake_force_n().sum()) > 0.0:
        train = consist.point_mass_train()
        summary["rotating_mass_factor"] = train.rotating_mass_factor
        summary["davis"] = [train.davis_a0, train.davis_a1, train.davis_a2]
        summary["max_service_decel_mps2"] = train.max_service_decel_mps2
    return summary


__all__ = [
    "BRAKE_PIPE_KPA",
    "CONSIST_PRESETS",
    "DISTRIBUTORS",
    "DP_RADIO_DELAY_S",
    "KINDS",
    "Consist",
    "Vehicle",
    "describe",
]
