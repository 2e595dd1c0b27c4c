"""The objective strategy's terms: small pure functions, each normalised to 0..1.

How it works: the `objective` strategy scores a robot for one instance as the weighted sum of
these terms (weights from `AllocationDef.weights`, `DEFAULT_WEIGHTS` for those left out) and
picks the feasible robot with the highest score. Higher is always better.

- mem_free: free memory left after adding the instance, over the largest robot's total memory.
- battery: battery percent / 100; a robot without a battery (None) scores 1 (mains power).
- rssi: -90 dBm -> 0, -30 dBm -> 1, linear between; a robot without a radio (None) scores 1.
- distance: closeness to the robots of the already-placed connected components: 1 on the same
  spot, 0 at `scale` metres (the distance threshold, else the spread of known positions) or
  farther; 0.5 when a position is unknown; the mean over those components.
- traffic_local: the share of the bytes/s to already-placed connected components that stays on
  this robot (their instances run here).
- load: 1 - CPU percent after adding the instance / 100.

mem_free and load are linear in what the instance needs and are not clamped below 0: a robot
that cannot hold the instance scores lower still, and because the need shifts every robot's
score by the same amount, the strategy can rank robots without it.
"""

from __future__ import annotations

DEFAULT_WEIGHTS: dict[str, float] = {
    "mem_free": 1.0,
    "battery": 1.0,
    "rssi": 1.0,
    "distance": 1.0,
    "traffic_local": 1.0,
    "load": 1.0,
}
"""Every term counts the same unless the system file says otherwise."""

RSSI_FLOOR_DBM = -90.0
"""RSSI that scores 0 (a link about to drop)."""
RSSI_CEIL_DBM = -30.0
"""RSSI that scores 1 (next to the access point)."""
UNKNOWN_CLOSENESS = 0.5
"""Closeness when either position is unknown: neither near nor far."""


def _clamp(x: float) -> float:
    return 0.0 if x < 0.0 else 1.0 if x > 1.0 else x


def mem_score(free_after: float, scale: float) -> float:
    """Free bytes left after adding the instance, as a fraction of `scale` bytes."""
    return free_after / scale if scale > 0 else 0.0


def battery_score(pct: float | None) -> float:
    """Battery level as 0..1; no battery (None) is mains power and scores 1."""
    return 1.0 if pct is None else _clamp(pct / 100.0)


def rssi_score(dbm: float | None) -> float:
    """Signal strength as 0..1 between RSSI_FLOOR_DBM and RSSI_CEIL_DBM; None (wired) is 1."""
    if dbm is None:
        return 1.0
    return _clamp((dbm - RSSI_FLOOR_DBM) / (RSSI_CEIL_DBM - RSSI_FLOOR_DBM))


def closeness_score(distance: float | None, scale: float) -> float:
    """1 at 0 m, 0 at `scale` m or farther, UNKNOWN_CLOSENESS when the distance is unknown."""
    if distance is None:
        return UNKNOWN_CLOSENESS
    if scale <= 0:
        return 1.0 if distance <= 0 else 0.0
    return _clamp(1.0 - distance / scale)


def traffic_local_score(local_bytes_per_s: float, total_bytes_per_s: float) -> float:
    """The share of the traffic to placed peers that would stay on this robot."""
    if total_bytes_per_s <= 0:
        return 0.0
    return _clamp(local_bytes_per_s / total_bytes_per_s)


def load_score(cpu_after_pct: float) -> float:
    """1 - CPU percent after adding the instance / 100."""
    return 1.0 - cpu_after_pct / 100.0
