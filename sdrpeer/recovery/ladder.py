"""The escalation ladder of one subject (a component on a robot, for one rule).

How it works: a rule lists its steps in order (Table III: standby_same_robot, restart,
standby_other_robot, launch_other_robot). Each fault of the subject asks `next_action(now,
available)` for the step to take:

- attempts older than `window_s` are forgotten; with none left the fault is fresh and the
  ladder starts again at its first step;
- otherwise the fault came back within the window after the last step was taken: that step was
  *unresolved*. A local step (restart, same-robot standby) is taken again while the local budget
  lasts (`max_attempts` local attempts within the window, all local steps together) and it is
  still available; any other step is not repeated: the ladder moves on;
- steps that are not available now are skipped (no standby on this robot -> restart; no
  standby on another robot -> launch there), and so are local steps once the budget is spent;
- a step whose execution failed (`outcome(now, ok=False)`) is not repeated either;
- past the last step, `next_action` returns None: the ladder is exhausted for this window.

Every time is passed in; nothing here reads a clock.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Attempt:
    """A step taken at `at`."""

    at: float
    index: int
    """Position of the step in the ladder."""
    failed: bool = False
    """Its execution failed (reported by `outcome`)."""


class Escalation:
    """Where one subject stands on its ladder."""

    def __init__(
        self, ladder: tuple[str, ...], local: Collection[str], max_attempts: int, window_s: float
    ) -> None:
        """`local`: the steps of `ladder` that count against the local budget of `max_attempts`
        within `window_s`."""
        if not ladder:
            raise ValueError("an escalation ladder needs at least one step")
        self.ladder = ladder
        self.local = frozenset(local)
        self.max_attempts = max_attempts
        self.window_s = window_s
        self.attempts: list[Attempt] = []
        """Steps taken within the window, oldest first."""

    def next_action(self, now: float, available: Collection[str]) -> tuple[int, str] | None:
        """The fault is here (again) at `now`: the step to take as (index, name), or None."""
        self._forget(now)
        start = 0
        if self.attempts:
            last = self.attempts[-1]
            step = self.ladder[last.index]
            repeat = step in self.local and not last.failed
            start = last.index if repeat else last.index + 1
        spent = self.local_attempts() >= self.max_attempts
        for index in range(start, len(self.ladder)):
            step = self.ladder[index]
            if step not in available or (spent and step in self.local):
                continue
            self.attempts.append(Attempt(now, index))
            return index, step
        return None

    def outcome(self, now: float, ok: bool) -> None:
        """The last step was carried out (`ok`) or could not be (then it is not repeated)."""
        if self.attempts and not ok:
            last = self.attempts[-1]
            self.attempts[-1] = Attempt(last.at, last.index, failed=True)

    def local_attempts(self) -> int:
        """Local steps taken within the window (as of the last call)."""
        return sum(1 for a in self.attempts if self.ladder[a.index] in self.local)

    def idle(self, now: float) -> bool:
        """No attempt within the window: the subject's state may be dropped."""
        self._forget(now)
        return not self.attempts

    def _forget(self, now: float) -> None:
        self.attempts = [a for a in self.attempts if now - a.at <= self.window_s]
