"""A component whose execution context the caller steps (sdrpeer.sdk.execution.Stepped)."""

from __future__ import annotations

from sdrpeer.sdk import Stepped
from tests.components_fixture import Counter


class SteppedCounter(Counter):
    """Counter's 1, 2, 3, ... on `out`, one per step instead of one per period."""

    execution = Stepped()  # type: ignore[assignment]  # Counter's is Periodic
