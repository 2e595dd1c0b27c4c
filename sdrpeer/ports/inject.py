"""Injecting values into InPorts: the agent as a sender of its own (rtinject, `ros2 topic pub`).

How it works: each `Target` is an InPort's data server address and name. `Injector` opens one
`Connection` (sdrpeer.dataplane) per target with the agent's data keys, so the receiving host
authenticates it like any other sender, and the port's message type id in its hello, so a typed
InPort of another type refuses it (the refusal comes back as the error). Its policy is
`push: fifo, full: block`, and the hello asks the receiving InPort for `full: block` too (an
acknowledged stream: bounded by the sender's window): nothing injected or replayed is dropped
at either end, whatever the port's own policy, and `send` waits while the queue is full (the
receiver's pace). `start` waits (bounded) until every connection is up and says which could
not connect and why; `close` hands over what is pending before it closes.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from dataclasses import dataclass
from typing import Any

from sdrpeer.dataplane import Connection
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.errors import PortToolError
from sdrpeer.sdk.policy import ConnectorPolicy

SOURCE = "sdrpeer-port.inject"
"""What the hello's `from` says (the receiving host logs it)."""
SEND_WITHIN = 30.0
"""Seconds `send` waits for room before it gives up on a receiver that takes nothing."""


@dataclass(frozen=True, slots=True)
class Target:
    """Where injected values go."""

    label: str
    """'Instance.port', for messages."""
    addr: str
    """The receiving host's data address (unix:///... or tcp://HOST:PORT)."""
    in_port: str
    type_id: str | None = None
    """The port's message type id (None: untyped)."""


class Injector:
    """One sending connection per target."""

    def __init__(self, targets: list[Target], keys: tuple[bytes, ...], *, buffer: int = 64) -> None:
        self.targets = targets
        policy = ConnectorPolicy(push="fifo", buffer=buffer, full="block")
        session = os.urandom(4).hex()
        auth = DataAuth(keys)
        self.conns = [
            Connection(
                f"port-inject-{session}-{i}",
                t.addr,
                t.in_port,
                SOURCE,
                policy,
                auth=auth,
                type_id=t.type_id,
                backoff=(0.05, 0.5),
                given={"push": "fifo", "full": "block"},
            )
            for i, t in enumerate(targets)
        ]
        self.sent = [0] * len(targets)

    async def start(self, within: float = 5.0) -> None:
        """Connect every target, within `within` s; PortToolError (502) names any that did not."""
        for conn in self.conns:
            conn.start()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(within):
                await asyncio.gather(*(c.wait_connected() for c in self.conns))
        failed = [
            f"{t.label}: {c.last_error or 'no answer'}"
            for t, c in zip(self.targets, self.conns, strict=True)
            if not c.connected
        ]
        if failed:
            await self.close()
            raise PortToolError("cannot connect to " + "; ".join(failed), 502)

    async def send(self, index: int, value: Any, within: float = SEND_WITHIN) -> None:
        """Queue one value for target `index`, waiting while its queue is full; PortToolError
        (504) when it stays full for `within` s (the receiver takes nothing)."""
        conn = self.conns[index]
        if not conn.offer(value):
            try:
                async with asyncio.timeout(within):
                    while not conn.offer(value):
                        await conn.drain()
            except TimeoutError:
                label = self.targets[index].label
                raise PortToolError(f"{label} took nothing for {within:g} s", 504) from None
        self.sent[index] += 1

    async def close(self, linger: float = 5.0) -> None:
        """Hand what is pending to the sockets (for up to `linger` s) and close."""
        await asyncio.gather(*(c.close(linger) for c in self.conns), return_exceptions=True)
