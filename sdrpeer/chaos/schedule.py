"""The chaos soak's faults, drawn from a seed (pure: the same seed gives the same schedule).

How it works: `schedule(seed, robots, duration_s, network)` walks time from the start to
`duration_s`, drawing the gap to the next fault (1-4 s) and its kind, weighted: a component
host SIGKILLed, an agent SIGKILLed (restarted 4-10 s later), the robot's RSSI or battery dropped
past the recovery rules (restored 5-12 s later), and, on a namespace lab (`network`), a
partition of a minority of the robots (healed 5-12 s later; one at a time) or packet loss of
30-50 % on a robot (cleared 8-15 s later). A fault that has an end holds its robots until then;
at most `(robots - 1) // 2` robots are held at once, so a majority of the fleet always works and
the fleet can recover. Every fault ends by `duration_s` (the soak then checks that the fleet
converges). Faults are `Fault` values; the runner (`sdrpeer.chaos.run`) carries them out.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field

__all__ = ["Fault", "schedule"]

KINDS = ("kill_host", "kill_agent", "rssi", "battery", "partition", "loss")
_WEIGHTS = {"kill_host": 4, "kill_agent": 2, "rssi": 2, "battery": 1, "partition": 2, "loss": 2}
_LENGTH = {
    "kill_agent": (4.0, 10.0),
    "rssi": (5.0, 12.0),
    "battery": (5.0, 12.0),
    "partition": (5.0, 12.0),
    "loss": (8.0, 15.0),
}


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault: what, when, on which robots, until when (kill_host has no end)."""

    at: float
    kind: str
    robots: tuple[str, ...]
    until: float | None = None
    amount: float = 0.0
    """loss: the share of packets dropped (0..1)."""
    pick: int = 0
    """kill_host: which ACTIVE host of the robot (index modulo their number)."""
    extra: dict[str, str] = field(default_factory=dict, compare=False)


def schedule(seed: int, robots: int, duration_s: float, network: bool) -> list[Fault]:
    """Faults for a soak of `duration_s` on robot-1 .. robot-N, ordered by time."""
    rng = random.Random(seed)
    names = [f"robot-{k}" for k in range(1, robots + 1)]
    kinds = [k for k in KINDS if network or k not in ("partition", "loss")]
    weights = [_WEIGHTS[k] for k in kinds]
    budget = max(1, (robots - 1) // 2)
    held: list[tuple[float, tuple[str, ...], str]] = []  # (until, robots, kind) still on
    out: list[Fault] = []
    t = rng.uniform(1.0, 3.0)
    while t < duration_s:
        held = [h for h in held if h[0] > t]
        busy = {r for _, rs, _ in held for r in rs}
        kind = rng.choices(kinds, weights)[0]
        free = [n for n in names if n not in busy]
        if kind == "partition" and any(k == "partition" for _, _, k in held):
            pass  # one partition at a time: a second would redraw the first
        elif kind == "kill_host":
            if free:
                out.append(Fault(t, kind, (rng.choice(free),), pick=rng.randrange(1000)))
        elif len(busy) < budget and free:
            low, high = _LENGTH[kind]
            until = min(duration_s, t + rng.uniform(low, high))
            if kind == "partition":
                size = rng.randint(1, min(budget - len(busy), len(free) - 1) or 1)
                group = tuple(sorted(rng.sample(free, size)))
            else:
                group = (rng.choice(free),)
            amount = rng.uniform(0.3, 0.5) if kind == "loss" else 0.0
            if until - t >= 2.0 and len(group) < len(names):
                out.append(Fault(t, kind, group, until, round(amount, 2)))
                held.append((until, group, kind))
        t += rng.uniform(1.0, 4.0)
    return out
