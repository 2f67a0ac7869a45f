"""The running ground's status (the admin port's ``status`` answer) as text, as
``railpilot ground status`` prints it: the server and its trains, each train's
deliveries, then the dispatch core's TSRs, restrictions and target points."""

from __future__ import annotations

from typing import Any


def status_lines(status: dict[str, Any], now_s: float) -> list[str]:
    """``status`` as lines of text; a TSR's time left is counted from ``now_s`` (wall clock
    [s], as the TSR's ``valid_until_s``)."""
    lines = [
        f"ground {status['ground_id']} on {status['host']}:{status['port']}: "
        f"{status['connections']} connections, {status['registered']} registered trains"
    ]
    for t in status["trains"]:
        info = t["running_info"]
        where = (
            f"km {info['position_km']:.3f} {info['speed_kmh']:.1f} km/h {info['direction']} "
            f"({info['age_s']:.1f} s ago{'' if info['valid'] else ', INVALID'})"
            if info
            else "no running info"
        )
        link = f"connected ({t['state']})" if t["connected"] else "not connected"
        state = "registered" if t["registered"] else "not registered"
        lines.append(f"  train {t['train_id']} {t['train_number'] or ''}: {link}, {state}, {where}")
        for session, s in t["tsrs"].items():
            lines.append(f"    TSR {session}: {s}")
        for target_id, s in t["target_points"].items():
            lines.append(f"    target point {target_id}: {s}")
        for number, s in t["dispatch_commands"].items():
            lines.append(f"    dispatch command {number}: {s}")
    dispatch = status.get("dispatch", {})
    for tsr in dispatch.get("tsrs", []):
        left = (tsr["valid_until_s"] - now_s) / 60.0
        until = f"{left:.0f} min left" if left > 0 else "expired"
        lines.append(
            f"TSR {tsr['session']}: {tsr['state']}, km {tsr['start_km']:.3f}-{tsr['end_km']:.3f} "
            f"{tsr['limit_kmh']:g} km/h, {until}, '{tsr['reason']}' by {tsr['set_by']}, "
            f"to train(s) {', '.join(map(str, tsr['trains'])) or 'none yet'}"
        )
    for r in dispatch.get("restrictions", []):
        where = r["block"] or f"km {r['start_km']:.3f}-{r['end_km']:.3f} ({r['track']})"
        lines.append(f"restriction {r['id']}: {r['reason']} on {where}")
    for train, target in dispatch.get("targets", {}).items():
        if target["km"] is not None:
            lines.append(
                f"target point {target['target_id']} for train {train}: km {target['km']:.3f} "
                f"signal {target['signal']} ({target['reason']})"
            )
    return lines
