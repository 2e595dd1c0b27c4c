"""A tap: a receiver of the agent's own that OutPorts are connected to, for print and record.

How it works: `Tap` starts a `DataServer` (sdrpeer.dataplane) on a Unix socket in a private
temporary directory (and TCP on loopback, which nothing here uses) with the agent's data keys,
so a host's connection to it is authenticated like any other. Each tapped OutPort gets an
in-port of the tap's (`t0`, `t1`, ...; `in_port(i)`), a `TapSink`: it stamps every frame with the
time it arrived (`clock`, nanoseconds) and keeps at most `limit` of them; past that it drops the
oldest and counts it, so a reader that stops reading never holds the robot up (and the
connection's policy, `push: new` for print, keeps the sender from waiting either). `next()`
gives `(index, received_ns, seq, value)` in arrival order. The sink does not
acknowledge (it is not an `AckingPort`), so the sending host keeps nothing for it.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import tempfile
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from sdrpeer.dataplane import DataServer
from sdrpeer.dataplane.auth import DataAuth

TapFrame = tuple[int, int, int, Any]
"""(index of the tapped port, received at (ns), seq on its connection, value)."""


class TapSink:
    """An InPort stand-in that keeps the newest `limit` frames for the reader."""

    def __init__(
        self, index: int, out: deque[TapFrame], wake: asyncio.Event, clock: Callable[[], int]
    ) -> None:
        self.index = index
        self._out = out
        self._wake = wake
        self._clock = clock
        self.received = 0
        """Frames that arrived."""
        self.refused = 0
        """Frames the data server refused (oversized, malformed)."""

    def deliver(self, value: Any, seq: int, conn: str) -> None:
        """Keep one frame (the deque drops the oldest when full: counted by `Tap`)."""
        self.received += 1
        self._out.append((self.index, self._clock(), seq, value))
        self._wake.set()

    def refuse(self) -> None:
        """Count one refused frame."""
        self.refused += 1


class Tap:
    """A private receiver for `ports` OutPorts."""

    def __init__(
        self,
        ports: int,
        keys: tuple[bytes, ...],
        *,
        limit: int = 1024,
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        self._frames: deque[TapFrame] = deque(maxlen=limit)
        self._wake = asyncio.Event()
        self.sinks = [TapSink(i, self._frames, self._wake, clock) for i in range(ports)]
        self._dir = tempfile.mkdtemp(prefix="sdrpeer-tap-")
        self.server = DataServer(  # a Unix socket in a private directory, no TCP listener
            self._resolve,
            tcp_host=None,
            unix_path=os.path.join(self._dir, "tap.sock"),
            auth=DataAuth(keys),
        )
        self._closed = False
        self._taken = 0

    @staticmethod
    def in_port(index: int) -> str:
        """The tap's in-port name for the tapped port at `index`."""
        return f"t{index}"

    def _resolve(self, name: str) -> TapSink | None:
        if name.startswith("t") and name[1:].isdigit() and int(name[1:]) < len(self.sinks):
            return self.sinks[int(name[1:])]
        return None

    @property
    def address(self) -> str:
        """Where a host on this robot dials the tap."""
        return f"unix://{self.server.addresses['unix']}"

    @property
    def dropped(self) -> int:
        """Frames that arrived and were dropped before the reader took them (it was slow)."""
        kept = len(self._frames)
        return sum(s.received for s in self.sinks) - kept - self._taken

    async def start(self) -> None:
        """Listen (a failure leaves nothing behind: the directory goes too)."""
        try:
            await self.server.start()
        except BaseException:
            await self.close()
            raise

    async def next(self, within: float) -> TapFrame | None:
        """The oldest frame not taken yet, waiting up to `within` s for one (None: none came)."""
        if not self._frames and not self._closed:
            self._wake.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(within):
                    await self._wake.wait()
        if not self._frames:
            return None
        self._taken += 1
        return self._frames.popleft()

    async def close(self) -> None:
        """Stop listening, remove the socket's directory."""
        self._closed = True
        self._wake.set()
        with contextlib.suppress(Exception):
            await self.server.close()
        shutil.rmtree(self._dir, ignore_errors=True)
