"""Stand-ins for tests of the data plane and of code built on it.

How it works: `RecordingPort` is an InPort that keeps what it receives; `StalledReceiver` is a
raw receiver that says ok to a hello and then stops reading until released, so the sender's
socket and queue fill up and its connector policy has to decide. (Tests wait on conditions with
tests/wait.py.)
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass
from typing import Any

from sdrpeer.dataplane.frames import FrameDecoder, encode_reply
from sdrpeer.dataplane.pending import PolicyLike


class RecordingPort:
    """An InPort stand-in: records (seq, value, conn) of every frame and counts refusals."""

    def __init__(self) -> None:
        self.frames: list[tuple[int, Any, str]] = []
        self.refused = 0

    def deliver(self, value: Any, seq: int, conn: str) -> None:
        """Record one frame."""
        self.frames.append((seq, value, conn))

    def refuse(self) -> None:
        """Count one refused frame."""
        self.refused += 1

    @property
    def seqs(self) -> list[int]:
        """The seqs received, in arrival order."""
        return [seq for seq, _, _ in self.frames]

    @property
    def values(self) -> list[Any]:
        """The values received, in arrival order."""
        return [value for _, value, _ in self.frames]


class StalledReceiver(asyncio.Protocol):
    """A receiver that answers the hello with ok, then reads nothing until `release()`."""

    def __init__(self) -> None:
        self.port = RecordingPort()
        self.transport: asyncio.Transport | None = None
        self._decoder = FrameDecoder()
        self._hello_seen = False
        self._released = False
        self._server: asyncio.Server | None = None

    async def start(self, path: str) -> str:
        """Listen on the Unix socket `path`; returns the address to dial."""
        loop = asyncio.get_running_loop()
        self._server = await loop.create_unix_server(lambda: self, path)
        return f"unix://{path}"

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        self._decoder.feed(data)
        if not self._hello_seen:
            if self._decoder.next_map() is None:
                return
            self._hello_seen = True
            assert self.transport is not None
            self.transport.write(encode_reply(None))
            if not self._released:
                self.transport.pause_reading()
        for seq, value in self._decoder.frames():
            self.port.deliver(value, seq, "stalled")

    def release(self) -> None:
        """Start reading (and recording frames), now or as soon as the sender is connected."""
        self._released = True
        if self.transport is not None:
            self.transport.resume_reading()

    async def close(self) -> None:
        """Stop listening and drop the connection."""
        if self.transport is not None:
            self.transport.abort()
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await self._server.wait_closed()


def make_policy(
    push: str = "all", buffer: int = 8, full: str = "overwrite", skip: int = 0
) -> PolicyLike:
    """The SDK's ConnectorPolicy when it is importable, else an equivalent stand-in."""
    try:
        from sdrpeer.sdk.policy import ConnectorPolicy  # noqa: PLC0415 - optional upper layer
    except ImportError:
        return _Policy(push, buffer, full, skip)
    return ConnectorPolicy(push, buffer, full, skip)  # type: ignore[arg-type]


@dataclass(frozen=True)
class _Policy:
    push: str
    buffer: int
    full: str
    skip: int

    def to_map(self) -> dict[str, object]:
        return {"push": self.push, "buffer": self.buffer, "full": self.full, "skip": self.skip}
