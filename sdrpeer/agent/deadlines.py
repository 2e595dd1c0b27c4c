"""The deadlines a second implementation of an agent or a component host must honour, per preset.

How it works: each `Deadline` names a setting, the protocol it binds and what the other side owes
before it runs out; its value in each preset is read from the preset itself
(`sdrpeer.agent.tuning.preset(name)`), or, for the few waits every preset shares (the host's
heartbeat, the data stream's hello, dial and drain), from the code that keeps them. `markdown()`
renders the table docs/protocol.md shows in its section "Deadlines per preset", and
tests/test_protocol_deadlines.py holds the doc to it, so the table cannot drift from the
presets. `python -m sdrpeer.agent.deadlines` prints it. Nothing here reads a clock.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass

from sdrpeer.agent.tuning import PRESETS, Tuning, preset
from sdrpeer.control.host_side import HEARTBEAT_INTERVAL
from sdrpeer.dataplane.connection import Connection
from sdrpeer.dataplane.server import DataServer
from sdrpeer.dataplane.service import ServiceClient
from sdrpeer.gossip.formulas import suspicion_min_timeout
from sdrpeer.gossip.wire import Codec

SMALL_FLEET = 10
"""The fleet size the suspicion rows are given for (the timeout grows with log10(n) above)."""


def _default(callable_: Callable[..., object], name: str) -> float:
    """The default value of parameter `name` of `callable_` (a wait kept in code, not presets)."""
    default = inspect.signature(callable_).parameters[name].default
    assert isinstance(default, int | float), f"{callable_.__qualname__}({name}=...) has no default"
    return float(default)


def _suspicion_min(t: Tuning) -> float:
    g = t.gossip
    return suspicion_min_timeout(g.suspicion_mult, SMALL_FLEET, g.probe_interval)


@dataclass(frozen=True, slots=True)
class Deadline:
    """One row of the table: a wait one side keeps, and what the other side owes within it."""

    protocol: str
    """The protocol it binds: gossip, election, control channel, data stream."""
    setting: str
    """Where it is set: a preset's field (`gossip.probe_timeout`) or the code's constant."""
    owed: str
    """What the other side must do before it runs out (or what happens when it does)."""
    seconds: Callable[[Tuning], float]
    """Its value in a preset, in seconds."""


DEADLINES: tuple[Deadline, ...] = (
    Deadline(
        "gossip",
        "gossip.probe_interval",
        "a robot pings one member this often (about); a member silent for a probe round is probed "
        "indirectly",
        lambda t: t.gossip.probe_interval,
    ),
    Deadline(
        "gossip",
        "gossip.probe_timeout",
        "a pinged member acks within this (scaled up to 9x by the prober's local health), else "
        "k others are asked to probe it",
        lambda t: t.gossip.probe_timeout,
    ),
    Deadline(
        "gossip",
        f"suspicion, {SMALL_FLEET} robots or fewer",
        "a suspected member refutes (a higher incarnation) within this, else it is declared dead "
        "(gossip.suspicion_mult x max(1, log10 n) x probe_interval at least)",
        _suspicion_min,
    ),
    Deadline(
        "gossip",
        f"suspicion at most, {SMALL_FLEET} robots or fewer",
        "the same with no confirmation from other members (x gossip.suspicion_max_mult)",
        lambda t: _suspicion_min(t) * t.gossip.suspicion_max_mult,
    ),
    Deadline(
        "gossip",
        "gossip.push_pull_interval",
        "mean time between two full-state exchanges with one peer (scaled up for large fleets)",
        lambda t: t.gossip.push_pull_interval,
    ),
    Deadline(
        "gossip",
        "gossip.dead_reap_time",
        "a dead or left member is forgotten this long after; coming back later is a new join",
        lambda t: t.gossip.dead_reap_time,
    ),
    Deadline(
        "gossip",
        "datagram freshness (Codec)",
        "a datagram's timestamp is at most this far behind the receiver's cluster time (the "
        "newest timestamp it accepted), else it is refused as stale",
        lambda t: _default(Codec, "freshness_s"),
    ),
    Deadline(
        "election",
        "election.grace",
        "the k-th alive, eligible robot in rank claims a vacant allocator role after k x this "
        "(the top one at once)",
        lambda t: t.election.grace,
    ),
    Deadline(
        "election",
        "election.startup_grace",
        "a freshly started robot claims nothing for this long (it first hears the fleet)",
        lambda t: t.election.startup_grace,
    ),
    Deadline(
        "election",
        "election.rejoin_grace",
        "the same for a robot restarted into a running fleet",
        lambda t: t.election.rejoin_grace,
    ),
    Deadline(
        "control channel",
        "supervisor.hello_timeout",
        "a host sends `hello` within this of being spawned, else it is killed",
        lambda t: t.supervisor.hello_timeout,
    ),
    Deadline(
        "control channel",
        "supervisor.command_timeout",
        "a host answers each command within this, else the command fails (the host is not "
        "killed for it)",
        lambda t: t.supervisor.command_timeout,
    ),
    Deadline(
        "control channel",
        "heartbeat interval (host)",
        "an initialized host sends a heartbeat this often",
        lambda t: HEARTBEAT_INTERVAL,
    ),
    Deadline(
        "control channel",
        "supervisor.heartbeat_timeout",
        "an initialized host silent this long is killed as hung (an instance's `watchdog:` "
        "overrides; 0: never)",
        lambda t: t.supervisor.heartbeat_timeout,
    ),
    Deadline(
        "control channel",
        "supervisor.exit_timeout",
        "after `exit`, a host exits within this, else it gets SIGTERM",
        lambda t: t.supervisor.exit_timeout,
    ),
    Deadline(
        "control channel",
        "supervisor.term_timeout",
        "after SIGTERM, a host exits within this, else it gets SIGKILL",
        lambda t: t.supervisor.term_timeout,
    ),
    Deadline(
        "control channel",
        "supervisor.eof_grace",
        "a host whose control channel closed exits within this, else it is killed",
        lambda t: t.supervisor.eof_grace,
    ),
    Deadline(
        "data stream",
        "receiver hello wait (DataServer)",
        "a sender's `hello` arrives within this of connecting, else the receiver closes",
        lambda t: _default(DataServer, "hello_timeout"),
    ),
    Deadline(
        "data stream",
        "sender hello wait (Connection)",
        "connecting and the receiver's `hello` reply take at most this, else the dial failed and "
        "the sender dials again",
        lambda t: _default(Connection, "hello_timeout"),
    ),
    Deadline(
        "data stream",
        "repoint drain (Connection)",
        "a repointed link's last acks arrive within this, else it is aborted",
        lambda t: _default(Connection, "drain_timeout"),
    ),
    Deadline(
        "data stream",
        "service dial (ServiceClient)",
        "connecting to a service and its `hello` reply take at most this, else the dial fails",
        lambda t: _default(ServiceClient, "dial_timeout"),
    ),
)
"""Every row of docs/protocol.md's deadlines table, in its order."""


def _seconds(value: float) -> str:
    return f"{value:.3g} s"


def table(names: tuple[str, ...] = tuple(PRESETS)) -> list[list[str]]:
    """One row per deadline: protocol, setting, what is owed, its value in each named preset."""
    tunings = [preset(name) for name in names]
    return [
        [d.protocol, f"`{d.setting}`", d.owed, *(_seconds(d.seconds(t)) for t in tunings)]
        for d in DEADLINES
    ]


def markdown(names: tuple[str, ...] = tuple(PRESETS)) -> str:
    """The table as docs/protocol.md holds it (a Markdown table, one line per row)."""
    head = ["protocol", "setting", "what the other side owes", *(f"`{n}`" for n in names)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(row) + " |" for row in table(names)]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(), end="")
