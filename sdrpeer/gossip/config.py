"""Membership and dissemination settings, with presets.

Every duration is in seconds. Formulas that use these live in `sdrpeer.gossip.formulas`. An
agent takes its settings from the preset its `--preset` names (`sdrpeer.agent.tuning`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any


@dataclass(frozen=True, slots=True)
class GossipConfig:
    """Tunables of the SWIM core. Use a preset (`lan()`, `fast_test()`) and `replace()` fields."""

    probe_interval: float = 0.15
    """Time between two probes sent by a robot (scaled by the local-health multiplier)."""
    probe_timeout: float = 0.075
    """Wait for a direct ack before indirect probes are sent (scaled by local health)."""
    confirm_round: bool = True
    """A failed probe round is repeated at once before the target is suspected: this squares the
    false-suspicion rate under packet loss (about 11 % -> 1.2 % of rounds at 30 % loss) for one
    more probe interval of detection time."""
    indirect_checks: int = 3
    """k: how many other members are asked to probe a target that missed its direct ack."""
    suspicion_mult: float = 3.2
    """Minimum suspicion timeout = suspicion_mult * max(1, log10(n)) * probe_interval. 3.2 (was
    3.5): every robot of 1,000 simulated ones sees a death within 1.9 s (median; 2.05 s at 3.5),
    and 10 to 1,000 simulated robots with 30 % loss on every link still declare no false death
    (nor do they at 2.0: the refutation mechanisms, not this timeout, keep them alive)."""
    suspicion_max_mult: float = 3.0
    """Maximum suspicion timeout = suspicion_max_mult * minimum; confirmations shrink it."""
    retransmit_mult: int = 4
    """Each update is sent retransmit_mult * ceil(log10(n + 1)) times by every robot."""
    gossip_interval: float = 0.1
    """Time between gossip rounds (only sent while there is something to spread)."""
    gossip_fanout: int = 4
    """Members each gossip round is sent to."""
    push_pull_interval: float = 5.0
    """Mean time between full-state exchanges with one random peer (scaled up for large N)."""
    reconnect_time: float = 3600.0
    """How long the address of a dead member is still tried in full-state exchanges (heals
    long partitions)."""
    dead_reap_time: float = 60.0
    """A dead or left member is forgotten after this long."""
    stale_verdict_time: float = 10.0
    """A death declared by a member that is dead in our view, or came back from the dead less
    than this long ago, is taken as a suspicion only: it was very likely declared on the far
    side of a partition and reaches us as the partition heals (the member it names refutes it;
    taken as a death, it made the majority lose members it could still hear)."""
    awareness_max: int = 8
    """Ceiling of the local-health score; timeouts are scaled by (1 + score)."""
    max_datagram: int = 1400
    """Size the core packs its datagrams to, in bytes (Wi-Fi MTU minus headers): updates and
    full-state chunks are batched under it. One entry bigger than that (a large record) is still
    sent alone, up to `datagram_limit`."""
    datagram_limit: int = 65000
    """Largest datagram sent or accepted at all, in bytes, envelope included (the codec's
    limit, `sdrpeer.gossip.wire.Codec`): a bigger one is refused as oversized. Near the UDP maximum:
    a robot must still take a large record that a peer sent alone."""
    packet_overhead: int = 48
    """Bytes the wire envelope adds to every datagram, budgeted (the header with its key id,
    nonce and receiver id, and the AEAD tag: 39 bytes, `sdrpeer.gossip.wire.OVERHEAD`)."""

    def with_(self, **changes: Any) -> GossipConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)


def lan() -> GossipConfig:
    """Robots on one Wi-Fi network: sub-2-second failure detection, tolerant of 30 % loss."""
    return GossipConfig()


def lab() -> GossipConfig:
    """Many agents on one busy machine: what trips is a process the scheduler did not run for a
    while, not a lost packet, so the probe waits 0.25 s for its ack (scaled up to 9x by local
    health) and a suspicion lasts 6.5 x 0.3 s = 1.95 s at least (5.85 s at most); the rest is
    `lan`."""
    return GossipConfig(probe_interval=0.3, probe_timeout=0.25, suspicion_mult=6.5)


def fast_test() -> GossipConfig:
    """Loopback tests: everything fast, short reaping so tests finish quickly."""
    return GossipConfig(
        probe_interval=0.1,
        probe_timeout=0.05,
        suspicion_mult=3.0,
        gossip_interval=0.05,
        push_pull_interval=1.0,
        dead_reap_time=10.0,
    )
