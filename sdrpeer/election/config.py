"""Election settings, with presets.

Every duration is in seconds. The grace period should cover a few gossip rounds: it is how long a
robot gives each higher-ranked robot to claim the vacant role before it claims it itself. An agent
takes its settings from the preset its `--preset` names (`sdrpeer.agent.tuning`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any


@dataclass(frozen=True, slots=True)
class ElectionConfig:
    """Tunables of the election core. Use a preset (`lan()`, `fast_test()`) and `with_()`."""

    grace: float = 1.0
    """How long a robot waits for each alive, eligible robot ranked above it to claim a vacant
    role: the k-th in rank claims after k * grace (the top one at once). A few gossip rounds,
    plus the spread of start times when a fleet boots together: robots started up to `grace`
    after a lower-ranked one still win the first election (0.5 s lost that race in the lab)."""
    startup_grace: float = 1.5
    """A freshly started robot claims nothing for this long, so that it first hears the cluster's
    records (the current allocator and the highest epoch) through gossip."""
    rejoin_grace: float = 6.0
    """The same for a robot that restarted into a running fleet (it knows an epoch from before):
    its allocator very likely still is, and on a busy or lossy network its claim may take an
    anti-entropy round (5 s in `lan`) to arrive; claiming sooner made two allocators whose plans
    reshuffled the standbys of the whole fleet (seen in the 10-robot chaos soak)."""
    preempt: bool = False
    """When True, an alive, eligible robot ranked above the current allocator takes the role from
    it (with a higher epoch). When False (the default) a healthy allocator keeps the role (but see
    `priority_window`). The agent's `preempt` setting and the system file's `allocation.preempt`
    turn it on too."""
    priority_window: float = 6.0
    """Priority counts at start: for this long after a fresh start (no epoch known from before),
    a robot whose priority is strictly higher than the allocator's takes the role from it, once it
    has heard the fleet (`startup_grace`). A fleet started one robot after the other so ends with
    its highest-priority robot as allocator, whichever robot claimed first, and a lone robot claims
    as soon as before. Equal priorities never preempt (health and name do not count here), and a
    robot restarted into its fleet (it knows an epoch) does not: only `preempt` does that. It
    must exceed `startup_grace` by the time a fleet's records take to arrive (a few gossip
    rounds on a busy machine); 0 turns it off."""

    def __post_init__(self) -> None:
        if min(self.grace, self.startup_grace, self.rejoin_grace, self.priority_window) < 0:
            raise ValueError(
                f"election grace periods must be >= 0 (grace={self.grace}, "
                f"startup_grace={self.startup_grace}, rejoin_grace={self.rejoin_grace}, "
                f"priority_window={self.priority_window})"
            )

    def with_(self, **changes: Any) -> ElectionConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)


def lan() -> ElectionConfig:
    """Robots on one Wi-Fi network, gossiping with the `lan` gossip preset (0.1 s rounds)."""
    return ElectionConfig()


def lab() -> ElectionConfig:
    """Many agents on one busy machine (the `lab` gossip preset): twice the `lan` graces, so a
    robot whose records are late because its agent was not scheduled still wins its rank."""
    return ElectionConfig(grace=2.0, startup_grace=3.0, rejoin_grace=12.0)


def fast_test() -> ElectionConfig:
    """Loopback tests and the simulator with the `fast_test` gossip preset (0.05 s rounds)."""
    return ElectionConfig(grace=0.25, startup_grace=0.75, rejoin_grace=1.5, priority_window=4.0)
