"""The sender's window of frames written but not acknowledged yet (pure: no I/O, no clock).

How it works: a receiver that acknowledges (docs/protocol.md section 2, "Acknowledgements")
writes back the seq up to which its component has taken every frame of the connection. Until
then the sender keeps each frame it wrote, encoded, in `Retention`: seqs are given at write time
and every written frame is kept, so the frames held are exactly seqs `base` .. `base + len - 1`
and need no numbers of their own. `ack(seq)` lets go of everything up to `seq`; `unacked()` is
what a new receiver gets replayed (a repoint, a reconnect, a crash of the receiver), with the
original seqs. `full` is the window: while it holds `max_frames` frames or `max_bytes` bytes the
sender writes nothing more (the frames wait in the connector's queue, where the policy decides),
so an unacknowledged backlog is bounded and never silently discarded.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence, Sized
from typing import Final, Generic, TypeVar

DEFAULT_FRAMES: Final = 65536
"""Frames a connection keeps unacknowledged at most (the window, in frames)."""
DEFAULT_BYTES: Final = 4 * 1024 * 1024
"""Bytes of encoded values it keeps at most (the window, in bytes; one frame may exceed it)."""

T = TypeVar("T", bound=Sized)


class Retention(Generic[T]):
    """Frames written and not acknowledged, oldest first."""

    __slots__ = ("acked", "base", "bytes", "items", "max_bytes", "max_frames")

    def __init__(
        self, max_frames: int = DEFAULT_FRAMES, max_bytes: int = DEFAULT_BYTES, first_seq: int = 1
    ) -> None:
        """`first_seq`: the seq the first frame written gets (a connection that starts being
        acknowledged after frames it already wrote)."""
        if max_frames < 1 or max_bytes < 1:
            raise ValueError("retention: the window must hold at least one frame and one byte")
        self.max_frames = max_frames
        self.max_bytes = max_bytes
        self.items: deque[T] = deque()
        """The encoded values held (seq `base` first)."""
        self.base = first_seq
        """The seq of items[0] (the next seq to be written, when nothing is held)."""
        self.acked = first_seq - 1
        """The highest seq acknowledged."""
        self.bytes = 0
        """Bytes held."""

    def written(self, items: Sequence[T]) -> None:
        """Frames just written, with the seqs following the last one held."""
        self.items.extend(items)
        self.bytes += sum(map(len, items))

    def wrote(self, item: T) -> None:
        """One frame just written (the latency path)."""
        self.items.append(item)
        self.bytes += len(item)

    def ack(self, seq: int) -> int:
        """The receiver took every frame up to `seq`: let go of them; returns how many.
        An ack for frames not written yet, or older than one already seen, changes nothing."""
        end = self.base + len(self.items) - 1
        if seq <= self.acked or seq > end:
            return 0
        self.acked = seq
        n = seq - self.base + 1
        items = self.items
        for _ in range(n):
            self.bytes -= len(items.popleft())
        self.base = seq + 1
        return n

    @property
    def full(self) -> bool:
        """True while the window is full: nothing more may be written until an ack."""
        return len(self.items) >= self.max_frames or self.bytes >= self.max_bytes

    def unacked(self) -> list[tuple[int, T]]:
        """(seq, encoded value) of every frame held, oldest first."""
        return list(enumerate(self.items, self.base))

    def __len__(self) -> int:
        return len(self.items)
