"""The simulated network: seeded delay, loss and partitions between numbered nodes.

How it works:
- nodes are small ints (their slot in the cluster); the cluster maps names and addresses to them;
- every datagram gets one `verdict(src, dst)`: a negative number means it is dropped, otherwise
  it is the one-way delay in seconds, `base_delay + uniform(0, jitter)`;
- a datagram is dropped when a partition puts src and dst in different groups, or with the loss
  rate of its link (a per-link override, else the global rate);
- all randomness comes from the one `random.Random` handed in, so a run is reproducible; the
  verdict draws nothing for a partitioned datagram and no loss draw when the rate is zero.
"""

from __future__ import annotations

import random
from collections.abc import Iterable, Sequence

DROPPED = -1.0
"""What `Network.verdict` returns for a datagram that never arrives."""


class Network:
    """Delay, loss and partitions for `n` nodes, drawn from one seeded RNG."""

    def __init__(
        self,
        n: int,
        rng: random.Random,
        *,
        base_delay: float = 0.001,
        jitter: float = 0.004,
        loss: float = 0.0,
    ) -> None:
        if base_delay < 0 or jitter < 0:
            raise ValueError(f"delays must be >= 0 (base_delay={base_delay}, jitter={jitter})")
        self.n = n
        self.base_delay = base_delay
        """Smallest one-way delay, seconds."""
        self.jitter = jitter
        """Uniform extra delay in [0, jitter), seconds."""
        self._loss = 0.0
        self.loss = loss
        self._random = rng.random
        self._links: dict[tuple[int, int], float] = {}
        self._group: list[int] | None = None
        self.dropped_loss = 0
        """Datagrams lost to the loss rates."""
        self.dropped_partition = 0
        """Datagrams dropped because a partition separated sender and receiver."""

    @property
    def loss(self) -> float:
        """Global loss rate in [0, 1] for links without an override."""
        return self._loss

    @loss.setter
    def loss(self, rate: float) -> None:
        self._loss = _check_rate(rate)

    def set_link_loss(self, a: int, b: int, rate: float, *, both_ways: bool = True) -> None:
        """Override the loss rate from `a` to `b` (and back unless both_ways is False)."""
        rate = _check_rate(rate)
        self._links[a, b] = rate
        if both_ways:
            self._links[b, a] = rate

    def clear_link_loss(self) -> None:
        """Drop every per-link override; the global rate applies again."""
        self._links.clear()

    def partition(self, groups: Sequence[Iterable[int]]) -> None:
        """Split the nodes: each group is a side; nodes named in no group form one more side."""
        rest = len(groups)
        group = [rest] * self.n
        for g, members in enumerate(groups):
            for node in members:
                if group[node] != rest:
                    raise ValueError(f"node {node} is in two partition groups")
                group[node] = g
        self._group = group

    def heal(self) -> None:
        """Remove the partition: every node reaches every other again."""
        self._group = None

    def partitioned(self, a: int, b: int) -> bool:
        """Whether a partition currently separates `a` from `b`."""
        return self._group is not None and self._group[a] != self._group[b]

    def verdict(self, src: int, dst: int) -> float:
        """The delay of one datagram from `src` to `dst`, or DROPPED."""
        group = self._group
        if group is not None and group[src] != group[dst]:
            self.dropped_partition += 1
            return DROPPED
        rate = self._links.get((src, dst), self._loss) if self._links else self._loss
        if rate and self._random() < rate:
            self.dropped_loss += 1
            return DROPPED
        return self.base_delay + self._random() * self.jitter


def _check_rate(rate: float) -> float:
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"a loss rate must be in [0, 1], got {rate}")
    return float(rate)
