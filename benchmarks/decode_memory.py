"""Benchmark: peak memory of ``railpilot link decode`` on worst-case inputs of 4 MiB.

Worst case = the most reports (and work) per input byte. A report needs a header byte
0x7E followed by a non-0x7E byte, so at most one report comes per 2 raw bytes: the input
``7E 01`` repeated (each pair a frame start cut short by the next header byte, a FRAMING
report; the last one truncated). Other candidates, each of the same size: back-to-back
minimal frames (a 40-byte heartbeat on the wire: the largest report per byte, every check
judged), authenticated heartbeats verified with a key file (an HMAC per 56 bytes),
maximal frames whose body is all 0x7E (every byte stuffed: the decoder's slow path), and
the hex forms of the first two (4 MiB of hex text is 2 MiB of bytes), plus hex text whose
comments hold a 4-byte UTF-8 character (Python then stores the text at 4 bytes a
character while parsing it).

Each input is decoded with ``--json`` and in text mode by a fresh ``railpilot`` process,
stdout read (and discarded) by this one; the child's own peak RSS comes from
``os.wait4`` (Linux reports ``ru_maxrss`` in KiB). ``baseline`` decodes an empty input:
the interpreter and the imports. The frame count comes from the totals at the end of the
JSON output. Prints one JSON object. Not a test: the goal (peak RSS under 150 MB) is
reported, never asserted.

Usage: python benchmarks/decode_memory.py [--mib 4] [--only NAME ...]
"""

from __future__ import annotations

import argparse
import json
import platform
import stat
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from railpilot.link import encode_frame

MiB = 1 << 20
GOAL_PEAK_RSS_MB = 150
TRAIN_ID = 1001
GROUND_ID = 1
KEY = bytes(range(32))
HEARTBEAT = 0x50
TS_US = 1_700_000_000_000_000
#: Runs the CLI exactly as the ``railpilot`` console script does.
CLI = "import sys; from railpilot.cli import main; sys.exit(main(sys.argv[1:]))"


def _repeat(unit: bytes, size: int) -> bytes:
    return (unit * (size // len(unit) + 1))[:size]


def _frames(size: int, make: Callable[[int], bytes]) -> bytes:
    """Frames ``make(sequence)`` back to back up to ``size`` bytes (the last one cut)."""
    out = bytearray()
    seq = 0
    while len(out) < size:
        out += make(seq)
        seq += 1
    return bytes(out[:size])


def _heartbeat(seq: int, key: bytes | None = None) -> bytes:
    return encode_frame(
        HEARTBEAT, TRAIN_ID, GROUND_ID, seq, TS_US + seq, 0, b"", 1 if key else 0, key
    )


def _stuffed(seq: int) -> bytes:
    # A DISPATCH_COMMAND (variable body) of 2039 bytes whose body is all 0x7E: every body
    # byte is stuffed on the wire; the body check fails.
    return encode_frame(0x40, GROUND_ID, TRAIN_ID, seq, TS_US + seq, TS_US, b"\x7e" * 2000)


def inputs(size: int) -> dict[str, tuple[Callable[[], bytes], bool]]:
    """name -> (maker of the file content, needs --keys)."""
    half = size // 2  # hex text holds one byte per two characters
    line = ("7e01" * 16 + " # \U0001f686\n").encode()  # 64 digits, a train in a comment
    return {
        "baseline": (lambda: b"", False),
        "raw-framing-pairs": (lambda: _repeat(b"\x7e\x01", size), False),
        "raw-min-frames": (lambda: _frames(size, _heartbeat), False),
        "raw-auth-frames": (lambda: _frames(size, lambda s: _heartbeat(s, KEY)), True),
        "raw-stuffed-frames": (lambda: _frames(size, _stuffed), False),
        "hex-framing-pairs": (lambda: _repeat(b"7e01", size), False),
        "hex-min-frames": (lambda: _frames(half, _heartbeat).hex().encode(), False),
        "hex-pairs-utf8-comment": (lambda: line * (size // len(line)), False),
    }


#: Runs argv[2:] and writes "<exit code> <child's ru_maxrss>" to the file argv[1]. A fresh,
#: small process (no site, no railpilot) per measurement: ru_maxrss of children is the
#: maximum over all children waited for, and Linux counts in a child's ru_maxrss the memory
#: of the process it was forked from (up to its exec), so it must not be this one.
PROBE = (
    "import resource, subprocess, sys; rc = subprocess.call(sys.argv[2:]); "
    "open(sys.argv[1], 'w').write(f'{rc} {resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}')"
)


def measure(argv: list[str], scratch: Path) -> tuple[float, float, bytes]:
    """Run ``argv``; return (its peak RSS [MB], wall time [s], the end of its stdout)."""
    result = scratch / "probe.txt"
    started = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(
            [sys.executable, "-S", "-c", PROBE, str(result), *argv],
            stdout=subprocess.PIPE,
            stderr=err,
        )
        assert proc.stdout is not None
        tail = b""
        while chunk := proc.stdout.read(1 << 16):  # read and drop the output, keep its end
            tail = (tail + chunk)[-4096:]
        proc.wait()
        seconds = time.perf_counter() - started
        code, maxrss = (int(x) for x in result.read_text().split())
        if proc.returncode != 0 or code != 0:
            err.seek(0)
            raise SystemExit(f"{argv} exited {code}: {err.read().decode()[-2000:]}")
    kib = maxrss if sys.platform != "darwin" else maxrss / 1024  # macOS reports bytes
    return kib / 1024, seconds, tail


def _totals(tail: bytes) -> dict[str, int]:
    """The totals that close the streamed JSON object."""
    text = tail.decode()
    return json.loads("{" + text[text.rindex('"count"') :])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mib", type=float, default=4.0, help="input size [MiB] [4]")
    parser.add_argument("--only", nargs="*", help="run only these inputs")
    args = parser.parse_args()
    size = int(args.mib * MiB)
    results: dict[str, dict[str, float | int]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        keys = Path(tmp) / "keys.toml"
        keys.write_text(
            f'[[train]]\nid = {TRAIN_ID}\nactive_key = 1\n[train.keys]\n1 = "{KEY.hex()}"\n'
        )
        keys.chmod(stat.S_IRUSR | stat.S_IWUSR)
        for name, (make, with_keys) in inputs(size).items():
            if args.only and name not in args.only:
                continue
            path = Path(tmp) / name
            path.write_bytes(make())
            n_bytes = path.stat().st_size
            argv = [sys.executable, "-c", CLI, "link", "decode", str(path)]
            if with_keys:
                argv += ["--keys", str(keys)]
            frames = 0
            for mode in ("json", "text"):
                flags = ["--json"] if mode == "json" else []
                rss_mb, seconds, tail = measure(argv + flags, Path(tmp))
                if mode == "json":
                    totals = _totals(tail)
                    frames = totals["count"]
                results[f"{name}/{mode}"] = {
                    "bytes": n_bytes,
                    "frames": frames,
                    "peak_rss_mb": round(rss_mb, 1),
                    "seconds": round(seconds, 2),
                }
                print(f"{name}/{mode}: {results[f'{name}/{mode}']}", file=sys.stderr)
    print(
        json.dumps(
            {
                "benchmark": "decode_memory",
                "inputs": results,
                "worst_peak_rss_mb": max(r["peak_rss_mb"] for r in results.values()),
                "goal_peak_rss_mb": GOAL_PEAK_RSS_MB,
                "python": platform.python_version(),
                "machine": platform.machine(),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
