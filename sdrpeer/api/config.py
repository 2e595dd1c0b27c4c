"""The API's connection limits (`sdrpeer.api.connections`), with presets like the other layers'.

Every duration is in seconds. An agent takes these from the preset its `--preset` names
(`sdrpeer.agent.tuning`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any


@dataclass(frozen=True, slots=True)
class ApiLimits:
    """How many connections the API keeps and how long it lets one wait. Use a preset (`lan()`,
    `fast_test()`) and `with_()`."""

    max_connections: int = 256
    """Connections kept open at once (the agent's other sockets need descriptors too)."""
    idle_timeout: float = 30.0
    """Seconds a connection may wait with nothing of a request received: longer than aiohttp
    clients (agents' peer calls) keep an idle connection (15 s), so a client never reuses one
    the server is closing."""
    header_timeout: float = 10.0
    """Seconds from a request's first byte to the end of its head (request line and headers):
    a client sends a head in one write; a slowloris sender dribbling one is closed then."""
    backlog: int = 1024
    """The listening socket's accept queue (the kernel caps it at net.core.somaxconn): a burst
    of connections waits there to be accepted (and shed) instead of having SYNs dropped, which
    would cost a caller in the burst a 1 s retransmission."""

    @property
    def accept_batch(self) -> int:
        """Connections accepted per event-loop turn (asyncio accepts up to its `backlog` argument
        per turn): a quarter of `max_connections`. A newcomer is admitted, then its first bytes
        are read, before at most two batches of newer connections are admitted, so half the
        table is still younger than it when shedding could reach it: a caller that sends its
        request at once is read before it is the oldest (with a batch of `backlog`, 1,024
        newcomers, a caller was shed unread under a churning flood)."""
        return max(1, self.max_connections // 4)

    def __post_init__(self) -> None:
        if self.max_connections < 1 or self.backlog < 1:
            raise ValueError("max_connections and backlog must be at least 1")
        if self.idle_timeout <= 0 or self.header_timeout <= 0:
            raise ValueError("idle_timeout and header_timeout must be positive")

    def with_(self, **changes: Any) -> ApiLimits:
        """A copy with some fields changed."""
        return replace(self, **changes)


def lan() -> ApiLimits:
    """Robots on one Wi-Fi network."""
    return ApiLimits()


def lab() -> ApiLimits:
    """Many agents on a few busy cores: `lan`'s (a request head is one write on any machine)."""
    return ApiLimits()


def fast_test() -> ApiLimits:
    """Loopback tests: `lan`'s (tests that want short deadlines pass their own limits)."""
    return ApiLimits()
