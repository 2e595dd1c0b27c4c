"""What to do so that the instances this robot hosts match the desired set (pure; time passed in).

How it works: `Reconciler.plan(now, desired, observed)` looks at every instance once and returns
at most one `Action` for each, in name order. Rules, in the order they are tried:

1. An instance with an action in flight gets nothing (until `done(name)`, or `action_timeout`
   after it was issued, in case the shell lost it). Transient states (STARTING, BACKOFF, CREATED,
   STOPPING, FINALIZED) too.
2. Not desired but running, or FAILED -> stop. Desired and stopped -> start. FAILED stays FAILED
   unless its spec changed (then start: someone fixed it). Running with a spec whose process
   fields (component, launcher, target, params) changed -> stop (the next pass starts it).
3. ERROR -> nothing (a person or the recovery layer resets it).
4. INACTIVE or ACTIVE: connections first. An observed connection that is no longer desired, or
   whose ports or policy changed -> disconnect (a new receiver instance is no reason: repoint).
   A desired connection not made yet -> connect, once its address is known (`to_addr`, else the
   receiver's data address); made to another address than the one now resolved -> repoint. A
   `pending` connection (its remote receiver's address is not known yet) is left as it was
   made: it is re-pointed once known, never dropped for it.
5. Then the lifecycle: ACTIVE is wanted when desired is active and the role is active (a standby
   is kept INACTIVE, warm). Activate only when every receiver the instance sends to that should be
   active already is (receivers before senders); deactivate a receiver only after the senders
   that go down with it. Inside a cycle of connections these orderings are ignored.

Standbys' starts are paced: a standby starts only while fewer than `max_starting` hosts are
starting (spawned or being spawned, not initialized yet: a host's start-up, Python and its
imports, is the most CPU an instance ever takes in one go), in name order, and never while an
instance that should end up ACTIVE waits to start. Those start at once: a recovery that launches
five cold components needs all five as soon as possible. A plan that puts twenty instances on a
robot spawned twenty interpreters at once; ten robots sharing two cores did so together, and the
agents, starved, missed their probes' deadlines and were declared dead (issue 30).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

from sdrpeer.runtime.spec import ConnectionSpec, InstanceSpec
from sdrpeer.vocabulary import InstanceState, LifecycleState, ProcessState

RUNNING: frozenset[InstanceState] = frozenset(
    {LifecycleState.INACTIVE, LifecycleState.ACTIVE, LifecycleState.ERROR}
)
_DOWN: frozenset[InstanceState] = frozenset(
    {ProcessState.STOPPED, ProcessState.STOPPING, LifecycleState.FINALIZED}
)
"""Not desired and nothing to stop: stopped, or on its way there."""
STARTING: frozenset[InstanceState] = frozenset({ProcessState.STARTING, LifecycleState.CREATED})
"""A host spawned (or being spawned) whose component is not initialized yet."""
KINDS = ("start", "stop", "activate", "deactivate", "connect", "disconnect", "repoint")


@dataclass(frozen=True, slots=True)
class Observed:
    """What the agent sees of one instance right now."""

    status: InstanceState
    """Its supervisor's state."""
    spec: InstanceSpec | None = None
    """The spec its current (or last) host was started with."""
    data_addr: str | None = None
    """Where senders on this robot reach it (from its hello), if it is running."""
    connections: Mapping[str, tuple[ConnectionSpec, str]] = field(default_factory=dict)
    """Connections made from it: id -> (spec, address it sends to)."""


@dataclass(frozen=True, slots=True)
class Action:
    """One step towards the desired set."""

    kind: str
    """One of KINDS."""
    instance: str
    """The instance it applies to (the sender, for connection actions)."""
    conn: ConnectionSpec | None = None
    """The connection (connect, repoint, disconnect)."""
    to: str | None = None
    """The data address (connect, repoint)."""


def _bare(c: ConnectionSpec) -> ConnectionSpec:
    """What makes a connection another one: its ports and policy, not where its receiver is
    (another address, robot or instance of the component: a repoint, which hands the frames
    the old receiver never took to the new one)."""
    return replace(c, to_addr=None, pending=False, to_instance="")


def _reach(desired: Mapping[str, InstanceSpec]) -> dict[str, set[str]]:
    """Instance -> every instance its data reaches, directly or through others."""
    edges = {n: {c.to_instance for c in s.connections} for n, s in desired.items()}
    out: dict[str, set[str]] = {}
    for start, targets in edges.items():
        seen: set[str] = set()
        stack = list(targets)
        while stack:
            node = stack.pop()
            if node not in seen:
                seen.add(node)
                stack.extend(edges.get(node, ()))
        out[start] = seen
    return out


class Reconciler:
    """Plans actions and remembers which are in flight."""

    def __init__(self, action_timeout: float = 30.0, max_starting: int = 0) -> None:
        self.action_timeout = action_timeout
        self.max_starting = max_starting
        """Hosts starting at once, at most (0: no limit); see the module docstring."""
        self.in_flight: dict[str, tuple[Action, float]] = {}

    def done(self, name: str) -> None:
        """The shell finished (or failed) the action it was running for `name`."""
        self.in_flight.pop(name, None)

    def plan(
        self,
        now: float,
        desired: Mapping[str, InstanceSpec],
        observed: Mapping[str, Observed],
    ) -> list[Action]:
        """The next actions; each is in flight from now on."""
        for name, (_, since) in list(self.in_flight.items()):
            if now - since >= self.action_timeout:
                del self.in_flight[name]
        reach = _reach(desired)
        actions = []
        starts = []
        for name in sorted(set(desired) | set(observed)):
            if name in self.in_flight:
                continue
            obs = observed.get(name, Observed(ProcessState.STOPPED))
            spec = desired.get(name)
            action = (
                _undesired(name, obs)
                if spec is None
                else _desired(spec, obs, desired, observed, reach)
            )
            if action is not None and action.kind == "start":
                starts.append(action)
            elif action is not None:
                self.in_flight[name] = (action, now)
                actions.append(action)
        for action in self._paced(starts, desired, observed):
            self.in_flight[action.instance] = (action, now)
            actions.append(action)
        return actions

    def _paced(
        self,
        starts: list[Action],
        desired: Mapping[str, InstanceSpec],
        observed: Mapping[str, Observed],
    ) -> list[Action]:
        """The starts that may go now: every would-be active's; standbys' as many as the limit
        leaves beside the hosts starting already (all of them without a limit)."""
        if self.max_starting <= 0:
            return starts
        actives = [a for a in starts if desired[a.instance].wants_active()]
        if actives:  # no standby starts in a pass that starts actives; later, the count gates
            return actives
        busy = {n for n, (a, _) in self.in_flight.items() if a.kind == "start"}
        busy |= {n for n, obs in observed.items() if obs.status in STARTING}
        return starts[: max(0, self.max_starting - len(busy))]


def _undesired(name: str, obs: Observed) -> Action | None:
    if obs.status in _DOWN:
        return None
    return Action("stop", name)


def _desired(
    spec: InstanceSpec,
    obs: Observed,
    desired: Mapping[str, InstanceSpec],
    observed: Mapping[str, Observed],
    reach: Mapping[str, set[str]],
) -> Action | None:
    name = spec.name
    changed = obs.spec is not None and not spec.same_process(obs.spec)
    if obs.status == ProcessState.STOPPED or (obs.status == ProcessState.FAILED and changed):
        return Action("start", name)
    if obs.status not in RUNNING:
        return None
    if changed:
        return Action("stop", name)
    if obs.status == LifecycleState.ERROR:
        return None
    action = _connection_action(spec, obs, observed)
    if action is not None:
        return action
    want = spec.wants_active()
    if (
        want
        and obs.status == LifecycleState.INACTIVE
        and _receivers_ready(spec, obs, desired, observed, reach)
    ):
        return Action("activate", name)
    if (
        not want
        and obs.status == LifecycleState.ACTIVE
        and _senders_down(name, desired, observed, reach)
    ):
        return Action("deactivate", name)
    return None


def resolve(conn: ConnectionSpec, observed: Mapping[str, Observed]) -> str | None:
    """The address a connection should send to now, or None while it is unknown."""
    if conn.pending:
        return None
    if conn.to_addr is not None:
        return conn.to_addr
    receiver = observed.get(conn.to_instance)
    if receiver is None or receiver.status not in RUNNING:
        return None
    return receiver.data_addr


def _connection_action(
    spec: InstanceSpec, obs: Observed, observed: Mapping[str, Observed]
) -> Action | None:
    wanted = {c.id: c for c in spec.connections}
    for cid in sorted(obs.connections):
        made, _ = obs.connections[cid]
        if cid not in wanted or _bare(made) != _bare(wanted[cid]):
            return Action("disconnect", spec.name, made)
    for conn in spec.connections:
        addr = resolve(conn, observed)
        if addr is None:
            continue
        if conn.id not in obs.connections:
            return Action("connect", spec.name, conn, addr)
        if obs.connections[conn.id][1] != addr:
            return Action("repoint", spec.name, conn, addr)
    return None


def _receivers_ready(
    spec: InstanceSpec,
    obs: Observed,
    desired: Mapping[str, InstanceSpec],
    observed: Mapping[str, Observed],
    reach: Mapping[str, set[str]],
) -> bool:
    for conn in spec.connections:
        if conn.id not in obs.connections and resolve(conn, observed) is not None:
            return False  # still to be made (it will be, next pass)
        receiver = desired.get(conn.to_instance)
        if receiver is None or not receiver.wants_active():
            continue
        if spec.name in reach.get(conn.to_instance, set()):
            continue  # a cycle: no order to respect
        if (
            observed.get(conn.to_instance, Observed(ProcessState.STOPPED)).status
            != LifecycleState.ACTIVE
        ):
            return False
    return True


def _senders_down(
    name: str,
    desired: Mapping[str, InstanceSpec],
    observed: Mapping[str, Observed],
    reach: Mapping[str, set[str]],
) -> bool:
    for sender, spec in desired.items():
        if sender == name or spec.wants_active() or sender in reach.get(name, set()):
            continue
        sends_here = any(c.to_instance == name for c in spec.connections)
        if (
            sends_here
            and observed.get(sender, Observed(ProcessState.STOPPED)).status == LifecycleState.ACTIVE
        ):
            return False
    return True
