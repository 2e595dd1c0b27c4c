"""The connector policy of a data connection (OpenRTM vocabulary), as in docs/protocol.md.

How it works: `ConnectorPolicy` is a frozen, validated dataclass; `from_map` reads the policy map
of a `connect` command or a data-stream hello (every key optional) and `to_map` writes it back.
Who applies what: the sending data plane applies a connection's policy to its send queue
(sdrpeer.dataplane.pending: skip, new, buffer, full, block backpressure through `drain()`). The
receiving `InPortRuntime` applies, per connection, the InPort's declared policy with the keys the
connection's own policy gives over it (`merged`: the data server registers it from the hello
with `InPortRuntime.connect(conn, policy)`) to its read queue: all/fifo queue every
frame, skip keeps one of every `skip + 1`, new keeps only the newest; when `buffer` frames wait,
overwrite evicts the oldest, drop refuses the newest, block keeps it (`wait_space` lets the
reader pause).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Final, Literal, cast

__all__ = ["FULL_POLICIES", "PUSH_POLICIES", "ConnectorPolicy"]

Push = Literal["all", "fifo", "skip", "new"]
Full = Literal["overwrite", "drop", "block"]

PUSH_POLICIES: Final = ("all", "fifo", "skip", "new")
FULL_POLICIES: Final = ("overwrite", "drop", "block")
_KEYS: Final = ("push", "buffer", "full", "skip", "encrypt")


@dataclass(frozen=True, slots=True)
class ConnectorPolicy:
    """How frames of one connection are queued at the receiving InPort."""

    push: Push = "all"
    """all/fifo: every frame is queued; skip: one of every `skip + 1`; new: only the newest."""
    buffer: int = 8
    """How many unread frames the InPort keeps for this connection's frames (>= 1)."""
    full: Full = "overwrite"
    """When the buffer is full: overwrite the oldest, drop the newest, or block the sender."""
    skip: int = 0
    """With push="skip": frames skipped after each one kept (>= 0)."""
    encrypt: bool = True
    """Between robots (authenticated TCP), the stream is encrypted (sdrpeer.dataplane.seal)."""

    def __post_init__(self) -> None:
        if self.push not in PUSH_POLICIES:
            raise ValueError(f"policy push: {self.push!r} not in {', '.join(PUSH_POLICIES)}")
        if self.full not in FULL_POLICIES:
            raise ValueError(f"policy full: {self.full!r} not in {', '.join(FULL_POLICIES)}")
        if type(self.buffer) is not int or self.buffer < 1:
            raise ValueError(f"policy buffer: {self.buffer!r} is not an integer >= 1")
        if type(self.skip) is not int or self.skip < 0:
            raise ValueError(f"policy skip: {self.skip!r} is not an integer >= 0")
        if type(self.encrypt) is not bool:
            raise ValueError(f"policy encrypt: {self.encrypt!r} is not true or false")

    @classmethod
    def from_map(cls, data: dict[str, Any] | None) -> ConnectorPolicy:
        """A policy from a protocol policy map; missing keys take defaults, unknown keys ignored."""
        if data is None:
            return cls()
        if not isinstance(data, dict):
            raise ValueError(f"policy: expected a map, got {type(data).__name__}")
        kw = {k: data[k] for k in _KEYS if k in data}
        return cls(
            push=cast(Push, kw.get("push", "all")),
            buffer=kw.get("buffer", 8),
            full=cast(Full, kw.get("full", "overwrite")),
            skip=kw.get("skip", 0),
            encrypt=kw.get("encrypt", True),
        )

    def merged(self, data: dict[str, Any] | None) -> ConnectorPolicy:
        """This policy with the keys `data` gives (a connection's own policy over a port's
        default: what the receiving InPort applies); unknown keys ignored, bad values raise."""
        if data is None:
            return self
        if not isinstance(data, dict):
            raise ValueError(f"policy: expected a map, got {type(data).__name__}")
        given = {k: data[k] for k in _KEYS if k in data}
        return replace(self, **given) if given else self

    def to_map(self) -> dict[str, Any]:
        """The protocol policy map (every key written)."""
        return {
            "push": self.push,
            "buffer": self.buffer,
            "full": self.full,
            "skip": self.skip,
            "encrypt": self.encrypt,
        }
