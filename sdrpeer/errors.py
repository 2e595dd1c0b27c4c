"""One error hierarchy for everything a user or a peer can get wrong.

Our own mistakes are ordinary exceptions (bugs); these are the errors that carry a message meant
for a person: what was wrong and where.
"""

from __future__ import annotations


class SdrpeerError(Exception):
    """Base of every error sdrpeer raises on purpose."""


class ConfigError(SdrpeerError):
    """A configuration file, flag or robot file is wrong (the message names file, line, field)."""


class WireError(SdrpeerError):
    """A datagram or frame could not be accepted; `reason` is the counter it is filed under."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail


class ScenarioError(ConfigError):
    """A scenario file is wrong."""


class ApiError(SdrpeerError):
    """A call to an agent's HTTP API failed (the message says which agent and why)."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status
        """The HTTP status the agent answered with, None when it could not be reached."""


class NotAllocator(SdrpeerError):
    """This robot is not the allocator; `leader` is the one it believes in (or None)."""

    def __init__(self, leader: str | None) -> None:
        super().__init__(leader)
        self.leader = leader
