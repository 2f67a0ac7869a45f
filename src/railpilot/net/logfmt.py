"""Structured (key=value) log lines for the network adapters, on the stdlib ``logging``.

``kv(logger, logging.INFO, "registered", train=1001, peer="127.0.0.1:5555")`` logs
``event=registered train=1001 peer=127.0.0.1:5555``. Values with spaces or quotes are
quoted so the line stays machine-splittable. Key material is never passed here.
"""

from __future__ import annotations

import logging
import sys


def _value(value: object) -> str:
    text = f"{value:.6g}" if isinstance(value, float) else str(value)
    if not text or any(c in text for c in ' "=\n'):
        return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    return text


def format_kv(event: str, **fields: object) -> str:
    parts = [f"event={_value(event)}"]
    parts += [f"{key}={_value(value)}" for key, value in fields.items()]
    return " ".join(parts)


def kv(logger: logging.Logger, level: int, event: str, **fields: object) -> None:
    """Log one key=value line (formatting is skipped when the level is disabled)."""
    if logger.isEnabledFor(level):
        logger.log(level, format_kv(event, **fields))


def setup_logging(level: int = logging.INFO) -> None:
    """Send railpilot.net logs to stderr as ``ts=... level=... logger=... event=...``."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(
        logging.Formatter(
            "ts=%(asctime)s.%(msecs)03d level=%(levelname)s logger=%(name)s %(message)s",
            datefmt="%Y-%m-%dT%H:%M:%S",
        )
    )
    root = logging.getLogger("railpilot")
    root.handlers[:] = [handler]
    root.setLevel(level)
    root.propagate = False
