"""What the data server needs from the ports it delivers to (sdrpeer.sdk's InPort fits both).

An `InPortLike` takes frames; an `AckingPort` also acknowledges what its component took, so
senders can keep and replay the rest (docs/protocol.md section 2, "Acknowledgements").
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

__all__ = ["AckingPort", "InPortLike"]


class InPortLike(Protocol):
    """What the data server needs from an InPort."""

    def deliver(self, value: Any, seq: int, conn: str) -> None:
        """Accept one received frame."""

    def refuse(self) -> None:
        """Count one refused (oversized or malformed) frame."""


class AckingPort(InPortLike, Protocol):
    """An InPort that acknowledges what its component took (sdrpeer.sdk.inport's does)."""

    def attach_stream(
        self, conn: str, session: str, next_seq: int, send: Callable[[int], None]
    ) -> str:
        """A socket of an acknowledged stream opened; acks go to `send`; returns the key its
        frames are delivered under."""

    def detach_stream(self, key: str, send: Callable[[int], None]) -> None:
        """That socket closed."""

    def acked(self, key: str) -> int:
        """The seq up to which the stream's frames were taken."""

    def flush_acks(self) -> None:
        """Send every acknowledgement due now."""
