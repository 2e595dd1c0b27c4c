"""When to restart a host that died: exponential backoff with a stability reset and a give-up.

How it works (pure, time passed in): `RestartPolicy.on_exit(started, now)` is called when a host
exits without being asked to. A run that lasted at least `stable_after` seconds clears the
failure count first. Then the count goes up by one; at `max_fast_failures` consecutive fast
failures the answer is None (give up: the instance is FAILED), otherwise the delay before the
next start: `initial * factor ** (failures - 1)`, capped at `maximum`.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class RestartConfig:
    """Restart backoff settings (seconds)."""

    initial: float = 0.1
    """Delay before the first restart."""
    factor: float = 2.0
    """Each further fast failure multiplies the delay by this."""
    maximum: float = 5.0
    """The delay never exceeds this."""
    stable_after: float = 30.0
    """A run at least this long resets the failure count."""
    max_fast_failures: int = 10
    """Give up (state FAILED) after this many consecutive fast failures."""


def backoff_delay(config: RestartConfig, failures: int) -> float:
    """The delay before restart number `failures` (1-based)."""
    return float(min(config.maximum, config.initial * config.factor ** max(0, failures - 1)))


class RestartPolicy:
    """Counts consecutive fast failures of one instance and says how long to wait."""

    def __init__(self, config: RestartConfig) -> None:
        self.config = config
        self.failures = 0

    def on_exit(self, started: float, now: float) -> float | None:
        """A host started at `started` died at `now`: the delay to restart, or None to give up."""
        if now - started >= self.config.stable_after:
            self.failures = 0
        self.failures += 1
        if self.failures >= self.config.max_fast_failures:
            return None
        return backoff_delay(self.config, self.failures)

    def reset(self) -> None:
        """Forget past failures (a person asked for a restart, or the spec changed)."""
        self.failures = 0
