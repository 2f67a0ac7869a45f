"""A decoded frame's report (:class:`~railpilot.link.decode.FrameReport`) as JSON-ready data
and as text: what ``railpilot link decode`` prints, one frame at a time.

The JSON form of a report::

    {"ok", "unstuffed" (hex), "header": {...} | null, "message": {"type", "fields"} | null,
     "verdicts": [{"check", "ok", "detail"}, ...]}
"""

from __future__ import annotations

from dataclasses import asdict, fields, is_dataclass
from typing import Any

from .decode import FrameReport
from .messages import MessageType


def report_dict(report: FrameReport) -> dict[str, Any]:
    """One frame's report as a JSON-ready dict (enums by name, bytes in hex)."""
    frame = report.frame
    header = None
    if frame is not None:
        try:
            name = MessageType(frame.message_type).name
        except ValueError:
            name = f"UNKNOWN_0x{frame.message_type:02x}"
        header = {
            "message_type": frame.message_type,
            "message_type_name": name,
            "source_id": frame.source_id,
            "destination_id": frame.destination_id,
            "sequence": frame.sequence,
            "timestamp_us": frame.timestamp_us,
            "echo_timestamp_us": frame.echo_timestamp_us,
            "key_id": frame.key_id,
            "mac": frame.mac.hex() if frame.mac is not None else None,
            "crc": f"{frame.crc:08x}",
            "body": frame.body.hex(),
        }
    message = None
    if report.message is not None:
        m = report.message
        message = {
            "type": type(m).__name__,
            "fields": {f.name: _jsonable(getattr(m, f.name)) for f in fields(m)},
        }
    return {
        "ok": report.ok,
        "unstuffed": report.raw.hex() if report.raw is not None else None,
        "header": header,
        "message": message,
        "verdicts": [
            {"check": v.check.value, "ok": v.ok, "detail": v.detail} for v in report.verdicts
        ],
    }


def report_text(number: int, report: FrameReport) -> str:
    """Frame ``number`` (1-based) as text: a header line, then a line per check's verdict
    and the message it carries, if any (no final newline)."""
    r = report_dict(report)
    h = r["header"]
    if report.truncated:
        lines = [f"frame {number}: {report.verdicts[0].detail}"]
    elif h is None:
        lines = [f"frame {number}: not a frame"]
    else:
        lines = [
            f"frame {number}: {h['message_type_name']} {h['source_id']} -> "
            f"{h['destination_id']} seq {h['sequence']} ts {h['timestamp_us']} "
            f"echo {h['echo_timestamp_us']} key {h['key_id']}: "
            f"{'OK' if r['ok'] else 'FAILED'}"
        ]
    for v in r["verdicts"]:
        mark = {True: "ok  ", False: "FAIL", None: "skip"}[v["ok"]]
        lines.append(f"  {mark} {v['check']:<11} {v['detail']}")
    if r["message"] is not None:
        lines.append(f"  message {r['message']['type']}: {r['message']['fields']}")
    return "\n".join(lines)


def _jsonable(value: Any) -> Any:
    if hasattr(value, "name") and hasattr(value, "value"):  # enums
        return value.name
    if isinstance(value, tuple):
        return [_jsonable(v) for v in value]
    if is_dataclass(value) and not isinstance(value, type):
        return {k: _jsonable(v) for k, v in asdict(value).items()}
    return value
