"""``railpilot link decode``: hex errors with their position, raw/hex detection, a frame cut
off by the end of the input, and the streamed output (text and one JSON object)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from railpilot.cli import main
from railpilot.link import (
    Heartbeat,
    RunningInfo,
    TravelDirection,
    TsrSet,
    decode_stream,
    encode_body,
    encode_frame,
    unstuff,
)
from railpilot.link.decode_report import report_dict

GROUND_ID = 1
TRAIN_ID = 1001
KEY_1 = bytes(range(32))
T_US = 1_700_000_000_000_000
INFO = RunningInfo(42, "K1234", "SS4-0123", TravelDirection.UP, 22.22, 123_456.78)
TSR = TsrSet(126, 1000.0, 2000.0, 12.5, 1_700_000_000.0, 1_700_003_600.0)
ALLOWED = "(allowed: 0-9 a-f A-F, whitespace, ':', '0x' prefixes, '#' comments)"


def frames() -> list[bytes]:
    """Three wire frames: a heartbeat up, running info up, a TSR down (authenticated)."""
    return [
        encode_frame(Heartbeat.TYPE, TRAIN_ID, GROUND_ID, 0, T_US, 0, b""),
        encode_frame(
            INFO.TYPE, TRAIN_ID, GROUND_ID, 1, T_US + 1, T_US, encode_body(INFO), 1, KEY_1
        ),
        encode_frame(
            TSR.TYPE, GROUND_ID, TRAIN_ID, 2, T_US + 2, T_US + 1, encode_body(TSR), 1, KEY_1
        ),
    ]


def decode(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes | str, *flags: str
) -> tuple[int, str, str]:
    path = tmp_path / "input"
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    else:
        path.write_bytes(content)
    code = main(["link", "decode", str(path), *flags])
    out, err = capsys.readouterr()
    return code, out, err


def expected_json(data: bytes) -> dict[str, object]:
    """What the streamed JSON must hold: decode_stream's reports and their totals."""
    reports = list(decode_stream(data))
    return {
        "frames": [report_dict(r) for r in reports],
        "count": len(reports),
        "ok": sum(r.ok for r in reports),
        "failed": sum(not r.ok for r in reports),
        "bytes": len(data),
        "truncated": any(r.truncated for r in reports),
    }


# --- bad hex: exit 2, its line and column, nothing on stdout -------------------------------


@pytest.mark.parametrize("flags", [[], ["--hex"]], ids=["detected", "--hex"])
def test_a_bad_hex_digit_names_its_line_column_and_character(
    flags: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lines = ["# three frames", *(f.hex() for f in frames())]
    lines[2] = lines[2][:16] + "g" + lines[2][17:]  # line 3, column 17
    code, out, err = decode(tmp_path, capsys, "\n".join(lines) + "\n", *flags)
    assert code == 2 and out == ""
    assert f"error: input: line 3, column 17: 'g' is not a hex digit {ALLOWED}" in err
    assert "endpoint" not in err and "nothing was decoded" in err


@pytest.mark.parametrize(
    ("text", "line", "column", "shown"),
    [
        ("7e01 ~0\n", 1, 6, "'~'"),  # 0x7E as a text character is no hex digit
        ("# ok\n0x7e 0x01\n7e x1\n", 3, 4, "'x'"),  # an 'x' that is no '0x' prefix
        ("7e01\n  7e0,1\n", 2, 6, "','"),
        ("7e01 # comment: ~ g x\n\t7e 01 zz\n", 2, 8, "'z'"),  # comments are skipped
        ("7e01\n7e\x0001\n", 2, 3, "'\\x00'"),
    ],
)
def test_every_kind_of_bad_character_is_placed_exactly(
    text: str,
    line: int,
    column: int,
    shown: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, err = decode(tmp_path, capsys, text)
    assert code == 2 and out == ""
    assert f"input: line {line}, column {column}: {shown} is not a hex digit" in err


def test_a_byte_that_is_not_utf8_is_named_by_its_value(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = decode(tmp_path, capsys, b"7e01\n7e\xff01\n")
    assert code == 2 and out == ""
    assert "input: line 2, column 3: byte 0xff is not a hex digit" in err
    # not printable: the message says why the input was read as hex
    assert "no frame start (bytes 0x7E 0x01)" in err and "--raw" in err


def test_a_raw_capture_without_a_frame_start_is_read_as_hex_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    version_2 = bytearray(frames()[0])
    version_2[1] = 2  # no 0x7E 0x01 anywhere now
    code, out, err = decode(tmp_path, capsys, bytes(version_2))
    assert code == 2 and out == ""
    assert "line 1, column 1: '~' is not a hex digit" in err and "--raw" in err
    code, out, _ = decode(tmp_path, capsys, bytes(version_2), "--raw", "--json")
    [frame] = json.loads(out)["frames"]
    assert code == 0 and frame["verdicts"][0]["check"] == "version"


def test_other_characters_are_shown_as_themselves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = decode(tmp_path, capsys, "7e01 # é is fine here\n7e é01\n")
    assert code == 2 and out == ""
    assert "input: line 2, column 4: 'é' is not a hex digit" in err and "--raw" not in err


def test_an_odd_number_of_digits_names_the_unpaired_digit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wires = [f.hex() for f in frames()]
    code, out, err = decode(tmp_path, capsys, "\n".join([wires[0], wires[1][:-1]]) + "  # end\n")
    assert code == 2 and out == ""
    column = len(wires[1]) - 1
    assert f"input: line 2, column {column}: odd number of hex digits" in err
    assert "hex digits in pairs" in err and "first run" not in err


def test_an_odd_number_of_digits_also_points_at_the_first_odd_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wires = [f.hex() for f in frames()]
    text = f"{wires[0]}\n{wires[1][:10]} {wires[1][11:]}\n{wires[2]}\n"  # one digit lost
    code, out, err = decode(tmp_path, capsys, text)
    assert code == 2 and out == ""
    assert f"line 3, column {len(wires[2])}: odd number of hex digits" in err
    assert "the first run of an odd number of digits starts at line 2, column 1" in err


def test_separators_prefixes_and_comments_give_the_same_frames(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wire = b"".join(frames())
    plain = decode(tmp_path, capsys, wire.hex(), "--json")
    spelled = "\ufeff# captured by hand\r\n" + "\n".join(
        ":".join(f"0x{b:02X}" for b in wire[i : i + 16]) + "  # line"
        for i in range(0, len(wire), 16)
    )
    fancy = decode(tmp_path, capsys, spelled, "--json")
    assert plain[0] == fancy[0] == 0
    assert json.loads(plain[1])["frames"] == json.loads(fancy[1])["frames"]


def test_an_unreadable_file_is_exit_2_and_speaks_of_decoding(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["link", "decode", str(tmp_path / "missing.hex")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "missing.hex: not a readable file" in err
    assert "endpoint" not in err and "nothing was decoded" in err


# --- raw or hex -----------------------------------------------------------------------------


def test_raw_bytes_are_detected_by_the_frame_start(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wire = b"".join(frames())
    code, out, _ = decode(tmp_path, capsys, wire, "--json")
    assert code == 0 and json.loads(out) == expected_json(wire)


def test_hex_and_raw_can_be_forced(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    wire = b"".join(frames())
    code, out, err = decode(tmp_path, capsys, wire, "--hex")
    assert code == 2 and out == "" and "line 1, column 1: '~' is not a hex digit" in err
    code, out, _ = decode(tmp_path, capsys, wire.hex(), "--raw")
    assert code == 0 and out == "no frames found\n"


def test_hex_and_raw_together_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["link", "decode", "-", "--hex", "--raw"])
    assert exit_.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err


# --- a frame cut off by the end of the input -------------------------------------------------


def cut_tsr() -> tuple[bytes, str]:
    """The three frames with the TSR's last 10 wire bytes cut off, and the report's detail."""
    wire = b"".join(frames())
    tsr = frames()[2]
    length = len(unstuff(tsr[1:]))  # the TSR (session 126 = 0x7E) holds a stuffed pair
    received = len(unstuff(tsr[1:-10]))
    assert received < length
    return wire[:-10], f"truncated: input ends after {received} of {length} bytes"


def test_a_truncated_last_frame_is_reported_in_text(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut, detail = cut_tsr()
    code, out, _ = decode(tmp_path, capsys, cut)
    assert code == 0
    lines = out.splitlines()
    assert f"frame 3: {detail}" in lines
    assert lines[-1].split() == ["FAIL", "framing", *detail.split()]


def test_a_truncated_last_frame_is_a_failed_framing_report_in_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut, detail = cut_tsr()
    code, out, _ = decode(tmp_path, capsys, cut.hex(), "--json")
    report = json.loads(out)
    assert code == 0
    assert (report["count"], report["ok"], report["failed"]) == (3, 2, 1)
    assert report["truncated"] is True and report["bytes"] == len(cut)
    last = report["frames"][-1]
    assert last["ok"] is False and last["header"] is None
    assert last["verdicts"] == [{"check": "framing", "ok": False, "detail": detail}]


# --- streamed output -------------------------------------------------------------------------


def test_json_of_a_good_capture_holds_the_frames_the_library_built(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wire = b"".join(frames())
    code, out, _ = decode(tmp_path, capsys, wire.hex(), "--json")
    report = json.loads(out)  # exactly one JSON object
    assert code == 0 and report == expected_json(wire)
    assert (report["count"], report["failed"], report["truncated"]) == (3, 0, False)
    heads = [(f["header"]["message_type"], f["header"]["sequence"]) for f in report["frames"]]
    assert heads == [(Heartbeat.TYPE, 0), (INFO.TYPE, 1), (TSR.TYPE, 2)]
    assert report["frames"][1]["message"]["fields"]["speed_mps"] == pytest.approx(22.22)
    assert report["frames"][2]["message"]["fields"]["session"] == 126


@pytest.mark.slow
def test_streamed_json_of_many_frames_equals_what_decode_stream_yields(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Good, damaged and cut frames and garbage, over many of the decoder's 4096-byte slices.
    good = frames()
    pieces = []
    for i in range(500):
        pieces += [good[i % 3], b"\x7e\x01\x00", good[(i + 1) % 3][:-3] + b"\x00", b"junk"]
    wire = b"".join(pieces)
    code, out, _ = decode(tmp_path, capsys, wire, "--json")
    report = json.loads(out)
    assert code == 0 and report == expected_json(wire)
    assert report["count"] >= 1500 and report["ok"] >= 500 and report["failed"] >= 500


def test_text_output_has_one_block_per_report(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wire = b"".join(frames()) * 40
    code, out, _ = decode(tmp_path, capsys, wire)
    headers = [line for line in out.splitlines() if line.startswith("frame ")]
    assert code == 0 and len(headers) == 120
    assert headers[-1].startswith("frame 120: TSR_SET 1 -> 1001 seq 2") and "OK" in headers[-1]


def test_an_empty_input_has_no_frames(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert decode(tmp_path, capsys, "")[:2] == (0, "no frames found\n")
    code, out, _ = decode(tmp_path, capsys, "# nothing\n", "--json")
    assert code == 0 and json.loads(out) == expected_json(b"")


# --- the real command, as a process -----------------------------------------------------------

CLI = "import sys; from railpilot.cli import main; sys.exit(main(sys.argv[1:]))"


def run_cli(*args: str, stdin: bytes) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(
        [sys.executable, "-c", CLI, "link", "decode", *args],
        input=stdin,
        capture_output=True,
        timeout=60,
        check=False,
    )


@pytest.mark.slow
def test_the_command_reads_stdin_and_prints_one_json_object() -> None:
    wire = b"".join(frames())
    done = run_cli("-", "--json", stdin=wire[:-5])
    assert done.returncode == 0 and done.stderr == b""
    report = json.loads(done.stdout)
    assert report == expected_json(wire[:-5]) and report["truncated"] is True


@pytest.mark.slow
def test_the_command_exits_2_on_bad_hex_with_nothing_on_stdout() -> None:
    done = run_cli("--json", stdin=b"7e01\n7e0g\n")
    assert done.returncode == 2 and done.stdout == b""
    assert b"input: line 2, column 4: 'g' is not a hex digit" in done.stderr
