"""Every timer and size of an agent as one tree, with its presets (`lan`, `fast_test`, `lab`).

How it works: each part keeps its own configuration dataclass and presets, declared and documented
next to the code that reads them: `sdrpeer.gossip.config`, `sdrpeer.election.config`,
`sdrpeer.recovery.config`, `sdrpeer.runtime.config` (the instance supervisors),
`sdrpeer.deploy.config` (the coordinator), `sdrpeer.agent.timers` (the agent itself) and
`sdrpeer.api.config` (the connections its HTTP API keeps, and their deadlines). A
`Tuning` holds one of each, and a preset of the tree is built one way: the same-named preset of
every part. The agent's `--preset` (or `preset:` in its config file) names one of
`sdrpeer.config.PRESET_NAMES` (the configuration checks names without loading every part); the
agent hands every part its sub-config (`sdrpeer.agent.agent.Agent`). Nothing here reads a clock.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from sdrpeer.agent import timers as agent_timers
from sdrpeer.agent.timers import AgentTimers
from sdrpeer.api import config as api
from sdrpeer.api.config import ApiLimits
from sdrpeer.deploy import config as deploy
from sdrpeer.deploy.config import DeployConfig
from sdrpeer.election import config as election
from sdrpeer.election.config import ElectionConfig
from sdrpeer.gossip import config as gossip
from sdrpeer.gossip.config import GossipConfig
from sdrpeer.recovery import config as recovery
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.runtime import config as runtime
from sdrpeer.runtime.config import SupervisorConfig


@dataclass(frozen=True, slots=True)
class Tuning:
    """One preset of every part's settings. Build it with `preset(name)`."""

    name: str
    """The preset's name (a key of `PRESETS`)."""
    gossip: GossipConfig
    """The SWIM core: probe, suspicion, dissemination and anti-entropy timers, datagram sizes."""
    election: ElectionConfig
    """The election core's grace periods (the coordinator's election shell runs it)."""
    recovery: RecoveryConfig
    """The recovery cores' sample staleness and settle time (local recovery, robot-wide
    conditions)."""
    supervisor: SupervisorConfig
    """Each component host's supervisor: command, hello, watchdog and stop timeouts, restart
    backoff (the agent sets `data_host` from its `--bind`)."""
    deploy: DeployConfig
    """The coordinator: its step periods, waits and retries."""
    agent: AgentTimers
    """The agent itself: record pacing, leaving, stopping."""
    api: ApiLimits
    """The HTTP API's connections: how many are kept, the idle and request-head deadlines."""

    def with_(self, **changes: Any) -> Tuning:
        """A copy with some sub-configs changed."""
        return replace(self, **changes)


def lan() -> Tuning:
    """Robots on one Wi-Fi network: sub-2-second failure detection, tolerant of 30 % loss.

    Every part's `lan()`."""
    return Tuning(
        "lan",
        gossip=gossip.lan(),
        election=election.lan(),
        recovery=recovery.lan(),
        supervisor=runtime.lan(),
        deploy=deploy.lan(),
        agent=agent_timers.lan(),
        api=api.lan(),
    )


def fast_test() -> Tuning:
    """Loopback tests: fast timers, short reaping; a busy machine makes it flap.

    Every part's `fast_test()`: a probe missed for 0.3 s to 0.9 s declares a robot dead, which
    a loaded machine's scheduler can cause on its own (a 5-robot lab on two busy cores declared
    a healthy robot dead and moved the allocator four times); tests that want it say so."""
    return Tuning(
        "fast_test",
        gossip=gossip.fast_test(),
        election=election.fast_test(),
        recovery=recovery.fast_test(),
        supervisor=runtime.fast_test(),
        deploy=deploy.fast_test(),
        agent=agent_timers.fast_test(),
        api=api.fast_test(),
    )


def lab() -> Tuning:
    """Many agents sharing a few busy cores (sdrpeer lab up): slower, no false deaths.

    Every part's `lab()`: the `lan` tree with the timeouts that a stalled process (not a lost
    packet) trips made long enough that the scheduler of a loaded machine does not: a robot
    must miss its probes for about 2 s (up to 6 s) before it is declared dead, a vacant
    allocator role waits 2 s per robot ranked above, and a host may be silent 5 s before it is
    killed as hung. Deaths are found in about 3 s instead of 1-2 s."""
    return Tuning(
        "lab",
        gossip=gossip.lab(),
        election=election.lab(),
        recovery=recovery.lab(),
        supervisor=runtime.lab(),
        deploy=deploy.lab(),
        agent=agent_timers.lab(),
        api=api.lab(),
    )


PRESETS: dict[str, Callable[[], Tuning]] = {"lan": lan, "fast_test": fast_test, "lab": lab}
"""Every preset of the tree, by the name `--preset` takes (`sdrpeer.config.PRESET_NAMES`)."""


def preset(name: str) -> Tuning:
    """The preset called `name`; ValueError names the known ones."""
    try:
        return PRESETS[name]()
    except KeyError:
        raise ValueError(f"unknown preset {name!r} (known: {', '.join(PRESETS)})") from None
