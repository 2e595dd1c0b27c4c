"""A component whose execution context the caller steps (sdrpeer.sdk.execution.Stepped)."""

from __future__ import annotations

from sdrpeer.sdk import Component, OutPort, Stepped


class SteppedCounter(Component):
    """Writes 1, 2, 3, ... on `out`, one per step."""

    execution = Stepped()
    out = OutPort("the count")

    def on_initialize(self) -> None:
        """From zero."""
        self.n = 0

    def on_execute(self) -> None:
        """One more."""
        self.n += 1
        self.out.write(self.n)
