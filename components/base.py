"""`RobotComponent`: the base of the demonstration components, with the paper's memory reserve.

How it works: every component of the paper's demonstration allocated a 500 MB region when it
started and freed it when it stopped, so that memory pressure was visible to the allocator.
`RobotComponent` declares a `reserve_mb` param (default 0); `on_activated` allocates that many
MiB as one bytearray and writes one byte in every page, so the kernel really backs it (a fresh
allocation is only address space until it is touched), and `on_deactivated`/`on_finalize` drop
it (CPython returns a block this large to the kernel with munmap, so RSS falls again).
Subclasses call `super().on_activated()` / `super().on_deactivated()` from their overrides.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Final

from sdrpeer.sdk import Component, Param

__all__ = ["PAGE", "MemoryReserve", "RobotComponent"]

PAGE: Final = 4096
MIB: Final = 1024 * 1024


class MemoryReserve:
    """A block of memory that is allocated and touched, or not held at all."""

    def __init__(self) -> None:
        self._block: bytearray | None = None

    @property
    def size(self) -> int:
        """Bytes currently held."""
        return len(self._block) if self._block is not None else 0

    def allocate(self, mb: int) -> None:
        """Hold `mb` MiB, every page written (replaces what was held)."""
        self.release()
        if mb <= 0:
            return
        n = mb * MIB
        block = bytearray(n)
        block[::PAGE] = b"\x01" * len(range(0, n, PAGE))
        self._block = block

    def release(self) -> None:
        """Drop the block (no-op when nothing is held)."""
        self._block = None


class RobotComponent(Component):
    """A Component that holds `reserve_mb` MiB of touched memory while ACTIVE."""

    reserve_mb = Param(int, 0, "MiB allocated and touched while ACTIVE (the paper: 500)", min=0)

    def __init__(self, name: str | None = None, params: Mapping[str, Any] | None = None) -> None:
        super().__init__(name, params)
        self.reserve = MemoryReserve()
        """The memory held while ACTIVE."""

    def on_activated(self) -> None:
        """Allocate and touch the reserve."""
        self.reserve.allocate(self.reserve_mb)

    def on_deactivated(self) -> None:
        """Free the reserve."""
        self.reserve.release()

    def on_finalize(self) -> None:
        """Free the reserve (if finalized from ERROR)."""
        self.reserve.release()
