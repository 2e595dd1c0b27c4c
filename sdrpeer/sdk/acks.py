"""What an InPort acknowledges to a sender: the seq up to which every frame was taken.

How it works (pure: the InPort calls it, the data server sends what it says): a sender that
keeps its frames until they are acknowledged (sdrpeer.dataplane.retention) opens each socket
with a session id and the first seq it will carry. `AckState` follows one such stream at the
InPort. A frame is *handled* when the component took it (`get`, `read`, iteration) or the port's
policy discarded it (overwrite, drop, skip, new): then it can never be needed again. Frames of
one connection leave the port's queue in order, so the acknowledged seq is simply the seq of the
last frame handled — except for a frame refused on arrival (drop, skip) while older frames of
the same connection still wait: its seq is remembered with the number of frames queued before
it, and acknowledged once those are handled. What is never acknowledged — frames still queued
when the instance stops, or lost with a crash — is what the sender replays to the component's
next instance.

Frames the InPort discarded because its buffer was full (overwrite, drop) are also counted per
stream (`dropped`), and each acknowledgement carries how many more since the one before, so the
sender knows what its receiver threw away (a sender's own queue counts
only its own drops: an InPort that overwrites with a slow consumer would otherwise lose frames
with nothing counting them on the sending side).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

__all__ = ["AckState", "SendAck"]

SendAck = Callable[[int, int], None]
"""Writes one acknowledgement to the sender: the seq, and how many more frames of this stream the
InPort discarded on a full buffer since the previous acknowledgement."""


class AckState:
    """One acknowledged stream (a connection id and a sender session) at one InPort."""

    __slots__ = ("acked", "deq", "dirty", "dropped", "drops", "enq", "reported", "send", "session")

    def __init__(self, session: str, next_seq: int, send: SendAck | None) -> None:
        self.session = session
        self.send = send
        """Where acknowledgements go (the current socket's), None while no socket is open."""
        self.acked = next_seq - 1
        """Every frame up to this seq was handled."""
        self.enq = 0  # frames of this stream queued (the InPort counts them)
        self.deq = 0  # of those, handled (taken or evicted)
        self.drops: deque[tuple[int, int]] = deque()  # (frames queued before it, seq)
        self.dropped = 0
        """Frames of this stream the InPort discarded because its buffer was full (overwrite,
        drop); what `skip` and `new` thin out by design is not counted."""
        self.reported = 0
        """Of those, how many acknowledgements have told the sender of."""
        self.dirty = False
        """True when `acked` or `dropped` moved since they were last sent."""

    def refused(self, seq: int, *, overflow: bool = True) -> None:
        """Frame `seq` was discarded on arrival (drop: `overflow`, the buffer was full; skip:
        thinned by design, not counted): handled once the older frames still queued are."""
        if overflow:
            self.dropped += 1
            self.dirty = True
        if self.enq == self.deq:
            self._advance(seq)
        else:
            self.drops.append((self.enq, seq))

    def taken(self, seq: int) -> None:
        """The oldest queued frame of this stream (`seq`) left the queue."""
        self.deq += 1
        upto = seq
        drops = self.drops
        while drops and drops[0][0] <= self.deq:
            upto = drops.popleft()[1]
        self._advance(upto)

    def evicted(self, seq: int) -> None:
        """The oldest queued frame of this stream (`seq`) was evicted by a newer one (overwrite
        on a full buffer)."""
        self.dropped += 1
        self.dirty = True
        self.taken(seq)

    def _advance(self, seq: int) -> None:
        if seq > self.acked:
            self.acked = seq
            self.dirty = True

    def flush(self) -> None:
        """Send `acked` and the drops not reported yet if either moved and a socket is open."""
        if self.dirty and self.send is not None:
            self.dirty = False
            more, self.reported = self.dropped - self.reported, self.dropped
            self.send(self.acked, more)
