"""The protocol's formulas as small pure functions (after memberlist's util.go / suspicion.go)."""

from __future__ import annotations

import math


def retransmit_limit(mult: int, n: int) -> int:
    """How many times each robot sends one update: mult * ceil(log10(n + 1))."""
    return mult * max(1, math.ceil(math.log10(n + 1)))


def suspicion_min_timeout(mult: float, n: int, interval: float) -> float:
    """Shortest suspicion timeout: mult * max(1, log10(n)) * probe interval."""
    node_scale = max(1.0, math.log10(max(1, n)))
    return mult * node_scale * interval


def suspicion_confirmations_wanted(mult: float, n: int) -> int:
    """k: independent confirmations that shrink a suspicion to its minimum (0 in tiny clusters)."""
    k = max(0, int(mult) - 2)
    return 0 if n - 2 < k else k


def suspicion_timeout(confirmations: int, k: int, min_t: float, max_t: float) -> float:
    """Lifeguard: max - (max - min) * log(c + 1) / log(k + 1), never below min."""
    if k < 1:
        return min_t
    frac = math.log(confirmations + 1) / math.log(k + 1)
    return max(min_t, max_t - (max_t - min_t) * frac)


def push_pull_scale(interval: float, n: int) -> float:
    """Full-state exchanges slow down above 32 robots: interval * (ceil(log2 n - log2 32) + 1)."""
    if n <= 32:
        return interval
    return interval * (math.ceil(math.log2(n) - 5.0) + 1)


def scaled(value: float, health: int) -> float:
    """A timeout or interval stretched by the local-health score (Lifeguard's LHM)."""
    return value * (1 + health)
