"""Epoch fencing: a robot applies a plan or command only if it is not older than what it holds.

How it works: plans and commands carry the `(epoch, issuer)` of the allocator that made them, the
same order the election uses for claims (`sdrpeer.election.state.ClaimKey`). The fence keeps the
highest key it has admitted or been told of: a strictly older epoch is refused, and so is another
issuer at the same epoch ranked below the one admitted (two simultaneous claims at one epoch: the
election keeps the higher name, and so does the fence). The holder's own key is admitted again and
again (every plan of the current allocator). `raise_to` moves the fence without a plan, when the
election adopts a newer allocator; `highest` is what an agent persists across restarts.
"""

from __future__ import annotations

from sdrpeer.election.state import ClaimKey


class Fence:
    """The highest (epoch, issuer) a robot has accepted; older plans and commands are refused."""

    __slots__ = ("highest", "refused")

    def __init__(self, highest: ClaimKey = (0, "")) -> None:
        self.highest: ClaimKey = highest
        """The highest (epoch, issuer) admitted or raised to."""
        self.refused = 0
        """How many plans or commands were refused as stale."""

    @property
    def epoch(self) -> int:
        """The highest epoch admitted."""
        return self.highest[0]

    def accepts(self, epoch: int, issuer: str) -> bool:
        """Whether a plan of `(epoch, issuer)` would be applied (the fence does not move)."""
        return (epoch, issuer) >= self.highest

    def admit(self, epoch: int, issuer: str) -> bool:
        """Admit a plan or command if it is not older than the fence (and move the fence up to
        it); a refusal is counted."""
        if (epoch, issuer) < self.highest:
            self.refused += 1
            return False
        self.highest = (epoch, issuer)
        return True

    def raise_to(self, epoch: int, issuer: str) -> None:
        """Refuse from now on anything older than `(epoch, issuer)` (never lowers the fence)."""
        self.highest = max(self.highest, (epoch, issuer))
