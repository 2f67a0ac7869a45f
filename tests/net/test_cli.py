"""The link commands of the CLI: key-file safety, decode on the golden vectors, help, and a
server driven end to end by the admin commands."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from railpilot.cli import main

SPEC = Path(__file__).resolve().parents[2] / "docs" / "protocol.md"
KEY_HEX = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f"


def _key_file(tmp_path: Path, mode: int) -> Path:
    path = tmp_path / "keys.toml"
    path.write_text(f'[[train]]\nid = 1001\nactive_key = 1\n[train.keys]\n1 = "{KEY_HEX}"\n')
    path.chmod(mode)
    return path


def _golden_wires() -> list[str]:
    blocks = re.findall(r"```golden-vector\n(.*?)```", SPEC.read_text(encoding="utf-8"), re.S)
    return [re.search(r"^wire: ([0-9a-f]+)$", b, re.M).group(1) for b in blocks]  # type: ignore[union-attr]


@pytest.mark.parametrize(
    "argv",
    [
        ["ground", "serve", "--port", "0"],
        ["onboard", "run", "--server", "127.0.0.1:1", "--train-id", "1001"],
        ["link", "decode", "-"],
    ],
)
def test_a_key_file_open_to_others_is_refused_with_exit_code_2(
    argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    keys = _key_file(tmp_path, 0o644)
    assert main([*argv, "--keys", str(keys)]) == 2
    out, err = capsys.readouterr()
    assert "mode 0o644" in err and "chmod 600" in err
    assert KEY_HEX not in out + err and KEY_HEX[:16] not in out + err


def test_the_server_refuses_to_run_without_keys_unless_told_to(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["ground", "serve", "--port", "0"]) == 2
    assert "--keys" in capsys.readouterr().err


def test_decode_reports_every_golden_vector_valid_with_the_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wires = _golden_wires()
    assert len(wires) >= 4
    hexfile = tmp_path / "frames.hex"
    hexfile.write_text("# golden vectors of docs/protocol.md\n" + "\n".join(wires) + "\n")
    keys = _key_file(tmp_path, 0o600)
    assert main(["link", "decode", str(hexfile), "--keys", str(keys), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["count"] == len(wires) and report["failed"] == 0
    names = [f["message"]["type"] for f in report["frames"]]
    assert names == ["Heartbeat", "RunningInfo", "TsrSet", "TsrSetAck"]
    running_info = report["frames"][1]
    assert running_info["message"]["fields"]["speed_mps"] == pytest.approx(22.22)
    auth = {v["check"]: v["ok"] for v in running_info["verdicts"]}["auth"]
    assert auth is True  # MAC verified with the key file


def test_decode_of_raw_bytes_flags_a_corrupted_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wire = bytearray(bytes.fromhex(_golden_wires()[0]))
    wire[20] ^= 0x01  # one bit flipped inside the frame
    raw = tmp_path / "frame.bin"
    raw.write_bytes(bytes(wire))
    assert main(["link", "decode", str(raw), "--json"]) == 0
    (frame,) = json.loads(capsys.readouterr().out)["frames"]
    assert frame["ok"] is False and frame["message"] is None
    assert {v["check"]: v["ok"] for v in frame["verdicts"]}["crc"] is False


def test_decode_rejects_bad_hex_with_exit_code_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.hex"
    bad.write_text("7e0")
    assert main(["link", "decode", str(bad), "--hex"]) == 2
    assert "hex digits in pairs" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv",
    [
        ["ground"],
        ["ground", "serve"],
        ["ground", "tsr", "set"],
        ["ground", "tsr", "cancel"],
        ["ground", "target"],
        ["ground", "dispatch"],
        ["ground", "status"],
        ["onboard", "run"],
        ["link", "decode"],
        ["link", "proxy"],
        ["link", "loadtest"],
    ],
)
def test_every_command_has_help(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--help"])
    assert exit_.value.code == 0
    assert "usage: railpilot" in capsys.readouterr().out


@pytest.mark.slow
def test_serve_answers_admin_commands_and_stops_on_sigterm(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    keys = _key_file(tmp_path, 0o600)  # a key for train 1001 only
    cmd = [sys.executable, "-m", "railpilot.cli", "ground", "serve", "--keys", str(keys)]
    cmd += ["--port", "0", "--admin-port", "0", "--seconds", "30"]
    cmd += ["--db", str(tmp_path / "ground.db")]  # not ./ground.db: every run starts afresh
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    try:
        port = admin_port = None
        deadline = time.monotonic() + 15.0
        assert proc.stderr is not None
        while admin_port is None and time.monotonic() < deadline:
            line = proc.stderr.readline()
            # --port 0 picks a free port and logs it (docs/link-operations.md)
            match = re.search(r"event=listening host=\S+ port=(\d+)", line)
            port = int(match.group(1)) if match else port
            match = re.search(r"event=admin_listening host=\S+ port=(\d+)", line)
            admin_port = int(match.group(1)) if match else None
        assert admin_port is not None and port is not None and port > 0
        assert main(["ground", "status", "--admin-port", str(admin_port), "--json"]) == 0
        status = json.loads(capsys.readouterr().out)
        assert status["ok"] and status["result"]["trains"] == []
        assert status["result"]["port"] == port
        # No train has registered: 'all' is refused with exit code 2.
        argv = ["ground", "dispatch", "--train", "all", "--text", "hold"]
        assert main([*argv, "--admin-port", str(admin_port)]) == 2
        assert "trains: 'all' is not allowed" in capsys.readouterr().err
        # Operator input the server refuses with exit code 2 and a field: message line.
        tsr = ["ground", "tsr", "set", "--session", "7", "--limit-kmh", "45"]
        tsr += ["--valid-until-min", "1", "--reason", "works", "--admin-port", str(admin_port)]
        argv = [*tsr, "--train", "1001", "--train", "2002", "--start-km", "1", "--end-km", "2"]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "trains: [2002] is not allowed: expected train ids that have a key" in err
        assert main([*tsr, "--train", "1001", "--start-km", "120", "--end-km", "120.0"]) == 2
        err = capsys.readouterr().err
        assert "end_km: 120.0 is not allowed: expected a km post at least 1 cm above" in err
        # A field the operation does not have (the old --valid-s) is refused by argparse.
        with pytest.raises(SystemExit) as caught:
            main([*tsr, "--valid-s", "60", "--start-km", "1", "--end-km", "2"])
        assert caught.value.code == 2
        capsys.readouterr()
        assert main(["ground", "status", "--admin-port", str(admin_port), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["result"]["trains"] == []  # nothing queued
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10.0) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5.0)


def test_onboard_run_gives_up_cleanly_when_the_time_is_up(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # Nothing listens on the port: the client backs off and stops after --seconds.
    argv = ["onboard", "run", "--server", "127.0.0.1:9", "--train-id", "1001", "--no-auth"]
    assert main([*argv, "--seconds", "0.5", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["registrations"] == 0 and summary["connects"] == 0
    assert os.environ.get("RAILPILOT_KEY") is None  # keys never come from the environment
