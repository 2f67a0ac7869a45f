"""Generate heavy_haul.toml: a synthetic heavy-haul line modelled on Shuohuang.

Run ``python -m railpilot.line.data.make_heavy_haul`` to rewrite heavy_haul.toml next to
this file (``--check`` only compares). The output is a pure function of the tables below:
no randomness, no clock, so the committed file and a fresh run are byte-identical (a test
keeps them so). docs/line-data.md says which numbers are published and which assumed.

Shape of the line (km posts increase from the origin, so loaded trains run UP):

- 590 km from a Shenchi South-like origin at 1,533 m (km 0) to a Huanghua Port-like
  terminus; 20 stations with 1,700 m loops.
- A 240 km descent to below 200 m: 7.5 per mille to Ningwu West, then the long
  12 per mille descents between Ningwu West and Longgong and on to km 90 (the longest
  unbroken one 32.3 km), easing to 2-6 per mille down to Xibaipo (km 238); then a plain
  falling gently to the coast. Loaded (UP) trains never climb more than the 4 per mille
  ruling grade; empty (DOWN) trains climb the 12 per mille.
- Station loops are level.
- Curves: dense and sharp (400-800 m) in the mountains, sparse and wide on the plain.
- Static limits, for ``freight_loaded`` and ``freight_empty``: 80 km/h line speed;
  75 km/h on curves under 600 m, 65 km/h under 450 m; 70 km/h over the turnout zones
  (loop +- 0.4 km) of intermediate stations and 45 km/h through the origin and terminus
  yards; loaded trains going UP 70 km/h on descents of 10 per mille or more.
- Fixed block: per direction a home signal 0.4 km before each loop, an exit signal at
  the loop's far end and automatic block signals dividing the line between stations into
  sections of about 2.5 km. Stop points 30 m before the exit signal.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from functools import cache
from pathlib import Path

LENGTH_KM = 590.0
START_ELEVATION_M = 1533.0
LOOP_M = 1700.0
CATEGORIES = ("freight_loaded", "freight_empty")

#: (id, name, centre km). Names of Shuohuang stations where a published fact places
#: them (origin, the Ningwu West-Longgong mountain section, Xibaipo at the foot of the
#: 240 km descent, Suning North at about km 420, the port); the rest are placeholders.
#: Every km post is assumed.
STATIONS: tuple[tuple[int, str, float], ...] = (
    (1, "Shenchi South", 1.5),
    (2, "Ningwu West", 24.0),
    (3, "Longgong", 58.0),
    (4, "Station 04", 90.0),
    (5, "Station 05", 122.0),
    (6, "Station 06", 155.0),
    (7, "Station 07", 188.0),
    (8, "Station 08", 214.0),
    (9, "Xibaipo", 238.0),
    (10, "Station 10", 268.0),
    (11, "Station 11", 298.0),
    (12, "Station 12", 328.0),
    (13, "Station 13", 358.0),
    (14, "Station 14", 390.0),
    (15, "Suning North", 422.0),
    (16, "Station 16", 455.0),
    (17, "Station 17", 490.0),
    (18, "Station 18", 525.0),
    (19, "Station 19", 558.0),
    (20, "Huanghua Port", 588.5),
)

#: Terrain (start km, end km, per mille + rising UP), covering the line; station loops
#: are then laid level over it.
TERRAIN: tuple[tuple[float, float, float], ...] = (
    (0.0, 3.0, 0.0),
    (3.0, 24.0, -7.5),
    (24.0, 58.0, -12.0),
    (58.0, 72.0, -12.0),
    (72.0, 74.0, -4.0),
    (74.0, 90.0, -12.0),
    (90.0, 122.0, -6.0),
    (122.0, 138.0, -4.0),
    (138.0, 140.0, 4.0),
    (140.0, 155.0, -4.0),
    (155.0, 188.0, -3.0),
    (188.0, 214.0, -2.0),
    (214.0, 240.0, -2.5),
    (240.0, 262.0, -1.0),
    (262.0, 264.0, 4.0),
    (264.0, 268.0, -1.5),
    (268.0, 300.0, -0.8),
    (300.0, 302.0, 3.0),
    (302.0, 330.0, -0.6),
    (330.0, 360.0, -0.6),
    (360.0, 362.0, 4.0),
    (362.0, 364.0, -4.0),
    (364.0, 390.0, -0.5),
    (390.0, 425.0, -0.4),
    (425.0, 455.0, -0.4),
    (455.0, 457.0, 2.0),
    (457.0, 490.0, -0.3),
    (490.0, 525.0, -0.3),
    (525.0, 558.0, -0.3),
    (558.0, 590.0, -0.4),
)

#: Curves: (first km, last km, spacing km, length km, radii cycled through).
CURVE_REGIONS: tuple[tuple[float, float, float, float, tuple[float, ...]], ...] = (
    (3.0, 24.0, 1.8, 0.5, (600.0, 800.0, 500.0, 1000.0)),
    (24.0, 58.0, 1.4, 0.5, (400.0, 450.0, 500.0, 600.0, 400.0, 800.0)),
    (58.0, 95.0, 1.8, 0.5, (600.0, 800.0, 500.0, 1000.0)),
    (95.0, 240.0, 3.5, 0.6, (800.0, 1000.0, 1200.0, 600.0)),
    (240.0, 588.0, 9.0, 0.8, (2000.0, 3000.0, 1500.0)),
)

LINE_SPEED_KMH = 80.0
CURVE_LIMITS_KMH: tuple[tuple[float, float], ...] = ((450.0, 65.0), (600.0, 75.0))
THROAT_KM = 0.4
THROAT_KMH = 70.0
YARD_KM = 0.6
YARD_KMH = 45.0
DESCENT_PERMILLE = -10.0
DESCENT_KMH = 70.0
BLOCK_KM = 2.5
HOME_KM = 0.4
STOP_BEFORE_EXIT_KM = 0.030


def _r(km: float) -> float:
    """A km post rounded to the metre."""
    return round(km, 3)


@cache
def loops() -> tuple[tuple[int, str, float, float, float], ...]:
    """(id, name, centre, loop start, loop end) [km] of every station."""
    half = LOOP_M / 2000.0
    return tuple((i, name, c, _r(c - half), _r(c + half)) for i, name, c in STATIONS)


@cache
def gradients() -> tuple[tuple[float, float, float], ...]:
    """Terrain with the station loops laid level: (start, end, per mille)."""
    cuts = sorted({a for a, _, _ in TERRAIN} | {LENGTH_KM} | {x for s in loops() for x in s[3:]})
    out: list[tuple[float, float, float]] = []
    for a, b in itertools.pairwise(cuts):
        mid = 0.5 * (a + b)
        level = any(ls <= mid <= le for *_, ls, le in loops())
        g = 0.0 if level else next(p for s, e, p in TERRAIN if s <= mid < e)
        if out and out[-1][2] == g:
            out[-1] = (out[-1][0], b, g)
        else:
            out.append((a, b, g))
    return tuple(out)


@cache
def curves() -> tuple[tuple[float, float, float], ...]:
    """(start, end, radius m), kept clear of the station loops and their throats."""
    out: list[tuple[float, float, float]] = []
    for first, last, spacing, length, radii in CURVE_REGIONS:
        k = 0
        start = first + 0.5 * spacing
        while start + length <= last:
            end = _r(start + length)
            clear = all(
                end < ls - THROAT_KM - 0.1 or start > le + THROAT_KM + 0.1 for *_, ls, le in loops()
            )
            if clear and (not out or start > out[-1][1]):
                out.append((_r(start), end, radii[k % len(radii)]))
                k += 1
            start = _r(start + spacing)
    return tuple(out)


def _limit(category: str, up: bool, a: float, b: float) -> float:
    """Static limit [km/h] on the elementary interval (a, b) [km]."""
    mid = 0.5 * (a + b)
    limit = LINE_SPEED_KMH
    for s, e, radius in curves():
        if s <= mid <= e:
            for below, kmh in CURVE_LIMITS_KMH:
                if radius < below:
                    limit = min(limit, kmh)
    stations = loops()
    for n, (*_, ls, le) in enumerate(stations):
        at_origin = n == 0 and mid <= le + YARD_KM
        at_terminus = n == len(stations) - 1 and mid >= ls - YARD_KM
        if at_origin or at_terminus:
            limit = min(limit, YARD_KMH)
        elif ls - THROAT_KM <= mid <= le + THROAT_KM:
            limit = min(limit, THROAT_KMH)
    if category == "freight_loaded" and up:
        for s, e, g in gradients():
            if s <= mid <= e and g <= DESCENT_PERMILLE:
                limit = min(limit, DESCENT_KMH)
    return limit


def speed_limits() -> list[tuple[str, str, float, float, float]]:
    """(category, direction, start, end, km/h): "both" where the two directions agree."""
    stations = loops()
    cuts = {0.0, LENGTH_KM}
    for s, e, _ in curves():
        cuts |= {s, e}
    for s, e, _ in gradients():
        cuts |= {s, e}
    cuts |= {_r(stations[0][4] + YARD_KM), _r(stations[-1][3] - YARD_KM)}
    for *_, ls, le in stations[1:-1]:
        cuts |= {_r(ls - THROAT_KM), _r(le + THROAT_KM)}
    edges = sorted(cuts)
    out: list[tuple[str, str, float, float, float]] = []
    for category in CATEGORIES:
        runs: dict[str, list[list[float]]] = {"both": [], "up": [], "down": []}
        for a, b in itertools.pairwise(edges):
            up, down = _limit(category, True, a, b), _limit(category, False, a, b)
            pieces = [("both", up)] if up == down else [("up", up), ("down", down)]
            for direction, kmh in pieces:
                run = runs[direction]
                if run and run[-1][1] == a and run[-1][2] == kmh:
                    run[-1][1] = b
                else:
                    run.append([a, b, kmh])
        entries = [(category, d, s, e, v) for d, run in runs.items() for s, e, v in run]
        out += sorted(entries, key=lambda t: (t[2], ("both", "up", "down").index(t[1])))
    return out


def signals() -> list[tuple[str, float, str, str]]:
    """(id, km, direction, kind), sorted by km."""
    out: list[tuple[str, float, str, str]] = []
    stations = loops()
    for sid, _, _, ls, le in stations:
        out += [
            (f"UH{sid:02d}", _r(ls - HOME_KM), "up", "home"),
            (f"UX{sid:02d}", le, "up", "exit"),
            (f"DH{sid:02d}", _r(le + HOME_KM), "down", "home"),
            (f"DX{sid:02d}", ls, "down", "exit"),
        ]
    for (*_, le0), (*_, ls1, _) in itertools.pairwise(stations):
        for prefix, direction, a, b in (
            ("U", "up", le0, _r(ls1 - HOME_KM)),
            ("D", "down", _r(le0 + HOME_KM), ls1),
        ):
            n = max(1, round((b - a) / BLOCK_KM))
            for j in range(1, n):
                km = _r(a + j * (b - a) / n)
                out.append((f"{prefix}{round(km * 10):04d}", km, direction, "block"))
    return sorted(out, key=lambda t: (t[1], t[2]))


def _fmt(km: float) -> str:
    return f"{km:.3f}"


def render() -> str:
    """The text of heavy_haul.toml."""
    lines = [
        "# GENERATED by src/railpilot/line/data/make_heavy_haul.py: do not edit by hand;",
        "# change the generator and run `python -m railpilot.line.data.make_heavy_haul`.",
        "# A synthetic heavy-haul line modelled on the published facts of Shuohuang",
        "# (docs/line-data.md: which numbers are published, which assumed).",
        "",
        'name = "heavy-haul"',
        'description = "Synthetic Shuohuang-like heavy-haul line (590 km, fixed block); '
        'km posts increase from the Shenchi South-like origin, so loaded trains run up"',
        "start_km = 0.0",
        f"end_km = {LENGTH_KM:.1f}",
        f"start_elevation_m = {START_ELEVATION_M:.1f}",
        "categories = [" + ", ".join(f'"{c}"' for c in CATEGORIES) + "]",
        "",
        "stations = [",
    ]
    for sid, name, centre, ls, le in loops():
        lines.append(
            f'  {{ id = {sid}, name = "{name}", km = {_fmt(centre)}, '
            f"loop_length_m = {LOOP_M:.1f}, stop_up_km = {_fmt(le - STOP_BEFORE_EXIT_KM)}, "
            f"stop_down_km = {_fmt(ls + STOP_BEFORE_EXIT_KM)} }},"
        )
    lines += ["]", "", "gradients = ["]
    for a, b, g in gradients():
        lines.append(f"  {{ start_km = {_fmt(a)}, end_km = {_fmt(b)}, permille = {g:.1f} }},")
    lines += ["]", "", "curves = ["]
    for a, b, r in curves():
        lines.append(f"  {{ start_km = {_fmt(a)}, end_km = {_fmt(b)}, radius_m = {r:.1f} }},")
    lines += ["]", "", "speed_limits = ["]
    for category, direction, a, b, kmh in speed_limits():
        where = "" if direction == "both" else f'direction = "{direction}", '
        lines.append(
            f'  {{ category = "{category}", {where}start_km = {_fmt(a)}, end_km = {_fmt(b)}, '
            f"limit_kmh = {kmh:.1f} }},"
        )
    lines += ["]", "", "signals = ["]
    for signal_id, km, direction, kind in signals():
        lines.append(
            f'  {{ id = "{signal_id}", km = {_fmt(km)}, '
            f'direction = "{direction}", kind = "{kind}" }},'
        )
    lines += ["]", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check`` compare) heavy_haul.toml next to this file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 if stale")
    args = parser.parse_args(argv)
    target = Path(__file__).with_name("heavy_haul.toml")
    text = render()
    if args.check:
        same = target.exists() and target.read_text(encoding="utf-8") == text
        print(f"{target}: {'up to date' if same else 'STALE'}", file=sys.stderr)
        return 0 if same else 1
    target.write_text(text, encoding="utf-8")
    print(f"wrote {target}", file=sys.stderr)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
