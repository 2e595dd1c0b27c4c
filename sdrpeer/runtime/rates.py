"""Per-port rates from two heartbeats' counters (pure: the times are passed in).

How it works: a host's heartbeat carries each port's counters since it started (frames and bytes,
in and out). `port_rates(before, after, seconds)` divides the growth of each by the seconds
between the two heartbeats; a counter that went down (a new host process) or a port that was
not there before gives no rate rather than a wrong one.
"""

from __future__ import annotations

from collections.abc import Mapping

RATED = ("frames_in", "bytes_in", "frames_out", "bytes_out")
"""The counters that get a per-second rate (`<name>_per_s`)."""


def port_rates(
    before: Mapping[str, Mapping[str, int]],
    after: Mapping[str, Mapping[str, int]],
    seconds: float,
) -> dict[str, dict[str, float]]:
    """Port -> `<counter>_per_s` for each counter of RATED that both heartbeats carry."""
    if seconds <= 0:
        return {}
    out: dict[str, dict[str, float]] = {}
    for port, now in after.items():
        then = before.get(port)
        if then is None:
            continue
        rates = {
            f"{key}_per_s": round((now[key] - then[key]) / seconds, 1)
            for key in RATED
            if key in now and key in then and now[key] >= then[key]
        }
        if rates:
            out[port] = rates
    return out
