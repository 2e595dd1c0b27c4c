"""Eligibility and coarse health of a robot, from its metrics and the allocation thresholds.

How it works: the caller (the agent) computes both for every robot from its gossip record and
puts them in that robot's `Candidate`.
- `eligible`: battery, RSSI and worst measured link loss inside the allocation thresholds of the
  system file (`sdrpeer.system.model.Thresholds`: battery_above_pct, rssi_above_dbm, loss_below);
  a threshold that is not set, or a metric the robot does not report, is not checked;
- `health_bucket`: the worst of three coarse levels 0..3 (battery by quarters, RSSI by 10 dB steps,
  loss by 1 / 5 / 15 %), so that ordinary noise in the metrics does not reorder robots (a rank
  that flapped would make preemption flap). Unknown metrics count as the top level.
Eligibility without hysteresis can flap around a threshold; an agent that sees that should hold a
change for a few samples before it reports it.
"""

from __future__ import annotations

from sdrpeer.system.model import Thresholds

TOP = 3
"""The best health bucket."""
BATTERY_STEPS = (25.0, 50.0, 75.0)
"""Battery percent from which buckets 1, 2 and 3 start."""
RSSI_STEPS = (-70.0, -60.0, -50.0)
"""RSSI in dBm from which buckets 1, 2 and 3 start."""
LOSS_STEPS = (0.15, 0.05, 0.01)
"""Link loss (0..1) below which buckets 1, 2 and 3 start."""


def eligible(
    thresholds: Thresholds,
    *,
    battery_pct: float | None,
    rssi_dbm: float | None,
    link_loss: float | None,
    leaving: bool = False,
) -> bool:
    """Whether a robot may hold the allocator role (inside every allocation threshold)."""
    if leaving:
        return False
    t = thresholds
    low_battery = (
        t.battery_above_pct is not None
        and battery_pct is not None
        and battery_pct <= t.battery_above_pct
    )
    weak_signal = (
        t.rssi_above_dbm is not None and rssi_dbm is not None and rssi_dbm <= t.rssi_above_dbm
    )
    lossy = t.loss_below is not None and link_loss is not None and link_loss >= t.loss_below
    return not (low_battery or weak_signal or lossy)


def health_bucket(
    *, battery_pct: float | None, rssi_dbm: float | None, link_loss: float | None
) -> int:
    """Coarse health 0..3: the worst of the battery, RSSI and link-loss levels."""
    levels = [TOP]
    if battery_pct is not None:
        levels.append(sum(battery_pct >= step for step in BATTERY_STEPS))
    if rssi_dbm is not None:
        levels.append(sum(rssi_dbm >= step for step in RSSI_STEPS))
    if link_loss is not None:
        levels.append(sum(link_loss < step for step in LOSS_STEPS))
    return min(levels)
