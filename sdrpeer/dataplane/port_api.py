"""What the data server needs from the ports it delivers to (sdrpeer.sdk's InPort fits both).

An `InPortLike` takes frames; an `AckingPort` also acknowledges what its component took, so
senders can keep and replay the rest (docs/protocol.md section 2, "Acknowledgements"), and
counts back what its policy discarded; a `PolicyPort` queues each connection's frames per the
connection's own policy (the hello's policy map over the port's default). A port may also
have `deliver_many(frames, conn)`, the frames of one read at once, oldest first (what the data
server calls when it is there: the SDK's InPort queues them in one loop). A `ServicePortLike`
answers the calls of a service binding (sdrpeer.sdk.services' provider fits).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

__all__ = ["AckingPort", "InPortLike", "PolicyPort", "SendAck", "ServicePortLike"]

SendAck = Callable[[int, int], None]
"""Writes one acknowledgement: the seq, and the frames of the stream the policy discarded."""


class InPortLike(Protocol):
    """What the data server needs from an InPort."""

    def deliver(self, value: Any, seq: int, conn: str) -> None:
        """Accept one received frame."""

    def refuse(self) -> None:
        """Count one refused (oversized or malformed) frame."""


class AckingPort(InPortLike, Protocol):
    """An InPort that acknowledges what its component took (sdrpeer.sdk.inport's does)."""

    def attach_stream(self, conn: str, session: str, next_seq: int, send: SendAck) -> str:
        """A socket of an acknowledged stream opened; acks go to `send`; returns the key its
        frames are delivered under."""

    def detach_stream(self, key: str, send: SendAck) -> None:
        """That socket closed."""

    def acked(self, key: str) -> int:
        """The seq up to which the stream's frames were taken."""

    def flush_acks(self) -> None:
        """Send every acknowledgement due now."""


class PolicyPort(InPortLike, Protocol):
    """An InPort that queues each connection's frames per that connection's policy."""

    def connection_policy(self, given: dict[str, Any] | None, *, acked: bool = True) -> Any:
        """The policy a connection whose hello gave the policy map `given` gets (`acked`: an
        acknowledged stream; ValueError when a value is bad)."""

    def connect(self, conn: str, policy: Any) -> None:
        """Register connection `conn` with that policy."""


class ServicePortLike(Protocol):
    """A provided service port (sdrpeer.sdk.services' `ServiceProviderRuntime` is one)."""

    interface_id: str
    """What a consumer's hello must name (`svc`)."""

    def serve(
        self, call_id: int, method: str, arg: Any, reply: Callable[[int, bool, Any], None]
    ) -> None:
        """Answer one call through `reply` (call id, ok, value or ``[kind, message]``), now or
        later."""
