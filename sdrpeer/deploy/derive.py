"""What one robot must host under a plan, as instance specs for its reconciler (pure).

How it works: every placement on the robot becomes an `InstanceSpec` (cold standbys are placed
but not launched). Only active instances send: each connection of the system whose sender's
active instance is here becomes a `ConnectionSpec` to the receiver's active instance. A service
binding (a connection from a consumer's service port to a provider's) is one like the others:
the consumer is its sender, the provider its receiver, so it is resolved, held pending and
re-pointed the same way. A receiver
on this robot is resolved by the reconciler from its host's hello; a receiver on another robot
by the data address that robot gossips for it (`Remote.data`). Until that address is known the
connection is `pending` (one already made stays as it is, to be re-pointed; none is made), and
the sender is kept INACTIVE unless it is ACTIVE already, so senders start after their receivers
across robots too. Likewise a sender waits for a remote receiver
to be ACTIVE, except inside a cycle of connections, where no order can be respected.
A component moving between alive robots is handed over break-before-make: `handover_waits`
names the active placements here whose component another alive robot still runs ACTIVE as its
active instance; the caller holds them INACTIVE (`hold`) until that copy stands down, or for a
bounded time (`DeployConfig.handover_wait`: the old robot may never hear of the plan).
The old side yields at once: `superseded` names the active placements here whose component a
robot holding a newer plan (one this robot's store would take) already runs ACTIVE as its active
instance. That is the old side of a healed partition, or of a move whose plan reached the new robot
first; it stands its copy down as soon as gossip shows the newer copy running, before it has
fetched the newer plan itself.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, replace

from sdrpeer.plan import Placement, Plan
from sdrpeer.runtime.spec import ConnectionSpec, InstanceSpec
from sdrpeer.system.model import ConnectionDef, SystemDef
from sdrpeer.vocabulary import InstanceRole, LifecycleState


@dataclass(frozen=True, slots=True)
class Remote:
    """An instance another robot gossips about."""

    robot: str
    state: str
    """Its InstanceState (as its record says)."""
    data: str | None
    """Its TCP data address, while its host runs."""
    component: str = ""
    """The component it is an instance of ("": not known)."""
    role: str = ""
    """active or standby, in the plan that robot holds ("": not known)."""


def reachable(system: SystemDef) -> dict[str, set[str]]:
    """component -> every component its data reaches (transitively), for cycle checks."""
    out: dict[str, set[str]] = {c.name: set() for c in system.components}
    edges: dict[str, set[str]] = {c.name: set() for c in system.components}
    for conn in system.connections:
        edges[conn.from_component].add(conn.to_component)
    for start, targets in edges.items():
        stack = list(targets)
        while stack:
            node = stack.pop()
            if node not in out[start]:
                out[start].add(node)
                stack.extend(edges.get(node, ()))
    return out


def handover_waits(
    plan: Plan, robot: str, remote: Mapping[str, Remote], active_here: Collection[str] = ()
) -> set[str]:
    """Active placements on `robot`, not ACTIVE yet, whose component another robot (alive: in
    `remote`) still runs ACTIVE as its active instance (see the module docstring)."""
    running = _running_elsewhere(robot, remote)
    return {
        p.instance
        for p in plan.on_robot(robot)
        if p.role == InstanceRole.ACTIVE
        and p.component in running
        and p.instance not in active_here
    }


def _running_elsewhere(
    robot: str, remote: Mapping[str, Remote], among: Collection[str] | None = None
) -> set[str]:
    """Components another robot (of `among`, when given) runs ACTIVE as its active instance."""
    return {
        r.component
        for r in remote.values()
        if r.robot != robot
        and r.state == LifecycleState.ACTIVE
        and r.role == InstanceRole.ACTIVE
        and (among is None or r.robot in among)
    }


def superseded(
    plan: Plan, robot: str, remote: Mapping[str, Remote], newer: Collection[str]
) -> set[str]:
    """Active placements on `robot` whose component a robot in `newer` (robots holding a plan
    newer than `plan`) runs ACTIVE as its active instance (see the module docstring)."""
    running = _running_elsewhere(robot, remote, newer)
    return {
        p.instance
        for p in plan.on_robot(robot)
        if p.role == InstanceRole.ACTIVE and p.component in running
    }


def specs_for_robot(
    plan: Plan,
    robot: str,
    remote: Mapping[str, Remote],
    active_here: Collection[str] = (),
    hold: Collection[str] = (),
) -> list[InstanceSpec]:
    """The instances `robot` must host under `plan`.

    `remote`: instance name -> what gossip says of it (instances on other robots);
    `active_here`: names of local instances that are ACTIVE now (never held back once running);
    `hold`: active placements to keep INACTIVE for now (a handover, see `handover_waits`).
    """
    system = plan.system
    if system is None:
        return []
    reach = reachable(system)
    specs = []
    for p in plan.on_robot(robot):
        if p.role == InstanceRole.STANDBY and p.mode == "cold":
            continue
        comp = system.component(p.component)
        conns: list[ConnectionSpec] = []
        ready = True
        if p.role == InstanceRole.ACTIVE:
            for c in system.connections:
                if c.from_component != comp.name:
                    continue
                receiver = plan.active_of(c.to_component)
                if receiver is None:
                    continue
                spec, ok = _connection(
                    c, receiver, robot, remote, reach, encrypt=system.streams.encrypt
                )
                conns.append(spec)
                ready = ready and ok
        desired = (
            LifecycleState.ACTIVE if ready or p.instance in active_here else LifecycleState.INACTIVE
        )
        if p.instance in hold:
            desired = LifecycleState.INACTIVE
        specs.append(
            InstanceSpec(
                name=p.instance,
                component=comp.name,
                launcher=comp.launcher,
                target=comp.target,
                params=comp.params,
                desired=desired,
                role=p.role,
                connections=tuple(conns),
                watchdog_s=comp.watchdog_s,
            )
        )
    return specs


def _connection(
    c: ConnectionDef,
    receiver: Placement,
    robot: str,
    remote: Mapping[str, Remote],
    reach: Mapping[str, set[str]],
    *,
    encrypt: bool = True,
) -> tuple[ConnectionSpec, bool]:
    """(the connection spec, pending while unresolvable; whether the sender may activate)."""
    policy = c.policy
    if not encrypt and "encrypt" not in dict(policy):  # the system's `streams: {encrypt: false}`
        policy = tuple(sorted((*policy, ("encrypt", False))))
    base = ConnectionSpec(
        id=c.id,
        out_port=c.from_port,
        to_instance=receiver.instance,
        in_port=c.to_port,
        policy=policy,
    )
    if receiver.robot == robot:
        return base, True
    seen = remote.get(receiver.instance)
    if seen is None or seen.robot != receiver.robot or seen.data is None:
        return replace(base, pending=True), False
    in_cycle = c.from_component in reach.get(c.to_component, set())
    ok = in_cycle or seen.state == LifecycleState.ACTIVE
    return replace(base, to_addr=seen.data), ok
