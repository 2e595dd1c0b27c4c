"""Shared-memory rings: big values between two processes on one machine, outside the socket.

How it works: on a ``unix://`` connection the sender creates a segment (a file in /dev/shm,
``sdrpeer-dp-<pid>-<token>``) and names it in its hello (its pages are allocated, all at once,
only when the first big value takes the ring: a connection of small values costs no memory).
A receiver that can map it answers ``{"ok": true, "shm": true}`` and unlinks the file at once;
the sender unlinks it too when the reply comes, whatever it says. From then on the segment has
no name: it lives exactly as long as one of the two processes maps it, so a crash of either side
leaks nothing. (A sender killed between creating the file and the receiver mapping it leaves a
name behind: `sweep` removes names whose pid is dead, each time a sender creates one.)

The segment is a byte ring of `size` bytes, positions counted from 0 forever (offset = position
mod size). The sender copies a value's msgpack encoding in one piece (never across the wrap:
when it would not fit before the end, it starts at the next lap) and writes the small frame
``[seq, position, length]`` to the socket instead of ``[seq, value]``. The receiver decodes the
value from its mapping (one copy: the delivered value never aliases the ring) and sends back the
position it has consumed up to, as a msgpack uint, once per batch of frames it read. The sender
overwrites nothing the receiver has not consumed: when a value does not fit in the free space,
`place` returns None, `blocked` is set, and the value waits until the next credit.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import re
import struct
from typing import Any, Final

import msgpack

from sdrpeer.errors import FrameError

SHM_DIR: Final = "/dev/shm"
DEFAULT_SIZE: Final = 8 * 1024 * 1024
"""Ring bytes per connection (a value larger than this goes through the socket)."""
_PREFIX: Final = "sdrpeer-dp-"
_NAME: Final = re.compile(r"^sdrpeer-dp-(\d+)-[0-9a-f]{16}$")
_REF32: Final = struct.Struct(">BBIBQBI")
_MADV_POPULATE_READ: Final = 22  # Linux 5.14
_MADV_POPULATE_WRITE: Final = 23
_unpackb: Final = msgpack.unpackb


def ref_frame(seq: int, pos: int, length: int) -> bytes:
    """The frame ``[seq, pos, length]`` that stands for a value in the ring."""
    if seq < 0x1_0000_0000:
        return _REF32.pack(0x93, 0xCE, seq, 0xCF, pos, 0xCE, length)
    return msgpack.packb([seq, pos, length])  # type: ignore[no-any-return]


def sweep(directory: str = SHM_DIR) -> int:
    """Unlink segments left by senders that died before their receiver mapped them."""
    removed = 0
    with contextlib.suppress(OSError):
        for name in os.listdir(directory):
            match = _NAME.match(name)
            if match is None or _alive(int(match.group(1))):
                continue
            with contextlib.suppress(OSError):
                os.unlink(os.path.join(directory, name))
                removed += 1
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # someone else's process
    return True


def _map(fd: int, size: int) -> mmap.mmap:
    return mmap.mmap(fd, size, flags=mmap.MAP_SHARED)


def _populate(mapping: mmap.mmap, advice: int) -> None:
    """Fault every page of the ring in at once (one call, not a fault per page per lap)."""
    with contextlib.suppress(OSError, ValueError):  # older kernels: pages come one by one
        mapping.madvise(advice)


class SenderRing:
    """The sender's side of a ring: places values, takes credits."""

    def __init__(self, path: str, mapping: mmap.mmap) -> None:
        self.path = path
        self.name = os.path.basename(path)
        self.size = len(mapping)
        self.blocked = False
        """True when the last `place` found no room (cleared by a credit)."""
        self._map = mapping
        self._view = memoryview(mapping)
        self._head = 0  # where the next value goes (absolute)
        self._populated = False
        self._tail = 0  # what the receiver consumed (absolute)

    @classmethod
    def create(cls, size: int = DEFAULT_SIZE, directory: str = SHM_DIR) -> SenderRing | None:
        """A new segment of `size` bytes, or None where shared memory is not available."""
        sweep(directory)
        path = os.path.join(directory, f"{_PREFIX}{os.getpid()}-{os.urandom(8).hex()}")
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
        except OSError:
            return None
        try:
            os.ftruncate(fd, size)
            mapping = _map(fd, size)
        except OSError:
            with contextlib.suppress(OSError):
                os.unlink(path)
            return None
        finally:
            os.close(fd)
        return cls(path, mapping)

    def offer_map(self) -> dict[str, Any]:
        """What the hello carries: {"name", "size"}."""
        return {"name": self.name, "size": self.size}

    def place(self, head: bytes, body: bytes) -> int | None:
        """Copy `head + body` into the ring; its position, or None (and `blocked`) if no room."""
        n = len(head) + len(body)
        size = self.size
        start = self._head
        offset = start % size
        if offset + n > size:  # not across the wrap: start the next lap
            start += size - offset
            offset = 0
        if start + n - self._tail > size:
            self.blocked = True
            return None
        view = self._view
        if not self._populated:  # the first big value: the ring is used, give it its pages
            self._populated = True
            _populate(self._map, _MADV_POPULATE_WRITE)
        if head:
            view[offset : offset + len(head)] = head
        view[offset + len(head) : offset + n] = body
        self._head = start + n
        return start

    def is_blocked(self) -> bool:
        """True when the last `place` found no room and no credit came since."""
        return self.blocked

    def credit(self, consumed: int) -> None:
        """The receiver consumed everything before `consumed`; FrameError if it cannot have."""
        if type(consumed) is not int or not self._tail <= consumed <= self._head:
            raise FrameError("malformed", f"shm credit {consumed!r} outside the ring")
        self._tail = consumed
        self.blocked = False

    def unlink(self) -> None:
        """Remove the segment's name (the mappings stay valid)."""
        with contextlib.suppress(OSError):
            os.unlink(self.path)

    def close(self) -> None:
        """Unlink and unmap (values already placed stay readable to the receiver)."""
        self.unlink()
        _release(self._view, self._map)


class ReceiverRing:
    """The receiver's side of a ring: decodes values out of it, tracks what it consumed."""

    def __init__(self, mapping: mmap.mmap, max_frame: int) -> None:
        self.size = len(mapping)
        self.max_frame = max_frame
        self.consumed = 0
        """Everything before this position was taken out."""
        self._checked = 0
        self._populated = False
        self._map = mapping
        self._view = memoryview(mapping)

    @classmethod
    def attach(cls, offer: object, max_frame: int, directory: str = SHM_DIR) -> ReceiverRing:
        """Map (and unlink) the segment a hello offered; ValueError or OSError when it cannot."""
        if not isinstance(offer, dict):
            raise ValueError("shm: expected a map")
        name, size = offer.get("name"), offer.get("size")
        if not isinstance(name, str) or _NAME.match(name) is None:
            raise ValueError(f"shm: bad segment name {name!r}")
        if type(size) is not int or size <= 0:
            raise ValueError(f"shm: bad size {size!r}")
        path = os.path.join(directory, name)
        fd = os.open(path, os.O_RDWR)
        try:
            os.unlink(path)
            if os.fstat(fd).st_size != size:
                raise ValueError(f"shm: segment is not {size} bytes")
            return cls(_map(fd, size), max_frame)
        finally:
            os.close(fd)

    def check(self, frame: list[Any]) -> list[Any]:
        """A ``[seq, pos, length]`` frame as it is, once its numbers are valid (FrameError if
        not); `take` decodes its value later, when it is delivered (so a batch of big values
        is not all alive at once: the allocator reuses the memory of the one before)."""
        seq, pos, n = frame
        if type(seq) is not int or type(pos) is not int or type(n) is not int or seq < 0:
            raise FrameError("malformed", "shm frame is not [uint, uint, uint]")
        offset = pos % self.size
        if pos < self._checked or n <= 0 or offset + n > self.size:
            raise FrameError("malformed", f"shm frame at {pos} ({n} bytes) outside the ring")
        if n > self.max_frame:
            raise FrameError("oversized", f"frame of {n} bytes, max {self.max_frame}")
        self._checked = pos + n
        return frame

    def take(self, frame: list[Any]) -> Any:
        """The value of a checked ``[seq, pos, length]`` frame (a copy: the ring may reuse its
        bytes at once); FrameError when it is not one msgpack value."""
        _, pos, n = frame
        offset = pos % self.size
        if not self._populated:
            self._populated = True
            _populate(self._map, _MADV_POPULATE_READ)
        try:
            value = _unpackb(self._view[offset : offset + n], raw=False, strict_map_key=False)
        except Exception as exc:
            raise FrameError("malformed", f"shm value: {type(exc).__name__}: {exc}") from None
        self.consumed = pos + n
        return value

    def close(self) -> None:
        """Unmap."""
        _release(self._view, self._map)


def _release(view: memoryview, mapping: mmap.mmap) -> None:
    with contextlib.suppress(BufferError):
        view.release()
        mapping.close()
