"""The allocator's one path from a reason to a new plan (pure: no clock, no I/O).

How it works: every plan the allocator issues comes from `change(reason, ...)`, whatever asked
for it — a deploy or undeploy (`Deploy`), the re-issue of a held plan under a new allocator's
epoch or a re-allocation after robots died or degraded (`Reissue`), a robot's recovery step that
changes who is active (`Recover`), a planned move (`Move`). The skeleton is the same for all:
the next version (`plan.version + 1` under the same epoch, else 1), the allocation inputs the
reason asks for (`_ask`), `place`, an `allocation.infeasible` log when nothing fits, and the log
lines of the new plan. The caller (`sdrpeer.deploy.core`) publishes what comes out.

Every new plan's explanation (`Plan.why`, made by the allocation core) is stamped here with the
reason and the plan that decided it (`explained`); a placement the allocation kept where it was
keeps the explanation of the plan that decided it, with this plan as the one that checked it
again, so `sdrpeer describe` tells why a component first went to its robot, not only that it
stayed.

What differs by reason:
- `Deploy`: the system as given, the robot that received it tried first, no robot left out;
- `Reissue`: the held plan, smallest change, `held` components kept where they are; with
  `recovery` the thresholds are relaxed (`placer.relaxed_for_recovery`) and missing standbys
  tolerated. When nothing fits, a plan of another epoch or allocator is re-issued unchanged
  under ours (adopting it loses nothing) and our own is kept; an unchanged allocation issues
  nothing;
- `Recover`: `standby_same_robot` swaps in the standby on that robot, the other steps avoid that
  robot for the component; `LookupError` for a component the system does not have;
- `Move`: `move.move_inputs` (pinned to a destination, or its robot avoided; `MoveError`);
- `Comply`: a `Move` without a destination, asked by continuous compliance
  (`sdrpeer.recovery.compliance`): every constraint applies, so the component lands where its
  Table I thresholds and its connections' Table II bounds hold now.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field, replace

from sdrpeer.alloc.core import NOT_IN_VIEW
from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.deploy.effects import Log
from sdrpeer.deploy.move import move_inputs, swap_to_standby
from sdrpeer.deploy.placer import Infeasible, place
from sdrpeer.deploy.view import ClusterState
from sdrpeer.eventlog import EventKind
from sdrpeer.plan import Plan
from sdrpeer.system.model import SystemDef
from sdrpeer.vocabulary import InstanceRole


@dataclass(frozen=True, slots=True)
class Deploy:
    """Allocate a system (None: undeploy)."""

    system: SystemDef | None
    origin: str
    """The robot that received the system (first_fit tries it first)."""


@dataclass(frozen=True, slots=True)
class Reissue:
    """Re-allocate the held plan under our epoch (smallest change)."""

    why: str
    """Logged as the allocation's reason."""
    recovery: bool = False
    """Components move because of a failure (relaxed thresholds, standbys may be short)."""


@dataclass(frozen=True, slots=True)
class Recover:
    """A robot's recovery step that changes who is active."""

    robot: str
    component: str
    instance: str
    action: str
    """standby_same_robot, standby_other_robot or launch_other_robot."""


@dataclass(frozen=True, slots=True)
class Move:
    """A planned move of a component's active (to `to`, or off its robot)."""

    component: str
    to: str | None


@dataclass(frozen=True, slots=True)
class Comply:
    """Move a component's active off a robot where its placement violates a constraint
    (`compliance.on_violation: replace`): a `Move` without a destination, logged as such."""

    component: str
    why: str
    """The violated constraint, as logged (`loss 0.3 not below 0.05 on Cam.image->Det.image`)."""


Reason = Deploy | Reissue | Recover | Move | Comply
"""Why the allocator allocates."""


@dataclass(frozen=True, slots=True)
class Context:
    """What every allocation needs besides the reason."""

    me: str
    """The allocator (this robot)."""
    epoch: int
    """Its epoch."""
    state: ClusterState
    excluded: frozenset[str] = frozenset()
    """Robots that must not receive components (degraded, or within their dwell)."""
    held: frozenset[str] = frozenset()
    """Components the disconnect policy keeps where they are (`disconnect.held_components`)."""


@dataclass(frozen=True, slots=True)
class Change:
    """What one allocation came to."""

    result: Plan | Infeasible | None
    """The plan to publish, why there is none, or None: nothing to publish."""
    logs: list[Log] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class _Ask:
    system: SystemDef | None
    view: ClusterView
    previous: Plan | None
    avoid: dict[str, set[str]] = field(default_factory=dict)
    recovery: bool = False
    held: frozenset[str] = frozenset()


def cluster_view(
    state: ClusterState, origin: str | None, exclude: Collection[str] = frozenset()
) -> ClusterView:
    """The allocator's view: every alive robot with a record, in first-fit order, except
    `exclude` (robots that must not receive components: degraded, or being left)."""
    names = [n for n in state.order if n in state.alive] or sorted(state.alive)
    robots = []
    for name in names:
        if name not in exclude:
            rec = state.alive[name]
            robots.append(RobotView(name, rec.metrics, rec.links, rec.instances, rec.launch))
    return ClusterView(tuple(robots), origin)


def change(reason: Reason, plan: Plan | None, ctx: Context) -> Change:
    """The plan `reason` asks for, from the held `plan` (see the module docstring)."""
    epoch, me = ctx.epoch, ctx.me
    version = plan.version + 1 if plan is not None and plan.epoch == epoch else 1
    logs: list[Log] = []
    ask = _ask(reason, plan, ctx)
    if isinstance(ask, Infeasible):
        return Change(ask)
    if ask.system is None:
        new = Plan(epoch, version, None, (), me)
    else:
        result = place(
            ask.system,
            ask.view,
            epoch=epoch,
            version=version,
            allocator=me,
            previous=ask.previous,
            avoid=ask.avoid,
            recovery=ask.recovery,
            held=ask.held,
        )
        if isinstance(result, Infeasible):
            logs.append(Log(EventKind.ALLOCATION_INFEASIBLE, {"report": str(result)}))
            if not isinstance(reason, Reissue):
                return Change(result, logs)
            assert plan is not None
            if plan.epoch == epoch and plan.allocator == me:
                return Change(None, logs)  # nothing better to issue: keep the plan we hold
            new = Plan(epoch, version, plan.system, plan.placements, me, why=plan.why)
        elif isinstance(reason, Reissue):
            assert plan is not None
            if result.placements == plan.placements and (plan.epoch, plan.allocator) == (epoch, me):
                return Change(None, logs)  # e.g. still no robot for a missing standby
            new = result
        else:
            new = result
    if isinstance(reason, Move | Comply) and plan is not None:
        new = replace(new, system=plan.system)  # the pin is for this allocation only
    left = sorted(ctx.state.alive.keys() - {r.name for r in ask.view.robots})
    new = explained(new, plan, _reason_text(reason, plan), left)
    return Change(new, logs + _logs(reason, plan, new, epoch))


EXCLUDED = "excluded: a robot-wide recovery condition holds on it, or it is within its dwell"
"""Why an alive robot the allocation left out of its view refused an instance."""


def explained(new: Plan, old: Plan | None, reason: str, excluded: Collection[str] = ()) -> Plan:
    """`new` with every explanation the allocation just made stamped with `reason` and `new`'s
    (epoch, version); a placement kept where `old` had it keeps `old`'s explanation of it. A
    placement the strategy's order chose, and a standby left out, also name the alive robots the
    allocation did not consider (`excluded`: degraded, or within their dwell)."""
    here = (new.epoch, new.version)
    before = {} if old is None else {w.instance: w for w in old.why}
    out = []
    for w in new.why:
        if w.decided_in != (0, 0):
            out.append(w)  # a plan re-issued as it was: its explanations stand
            continue
        prior = before.get(w.instance)
        if w.how == "kept" and prior is not None and prior.robot == w.robot:
            out.append(replace(prior, checked_in=here))
        else:
            ruled_out = w.ruled_out
            if w.how in ("ranked", "preferred", "left_out"):  # robots it could have gone to
                ruled_out = _with_excluded(ruled_out, excluded)
            stamped = replace(w, reason=reason, decided_in=here, checked_in=here)
            out.append(replace(stamped, ruled_out=ruled_out))
    return replace(new, why=tuple(out))


def _with_excluded(
    ruled_out: tuple[tuple[str, str], ...], excluded: Collection[str]
) -> tuple[tuple[str, str], ...]:
    """`ruled_out` naming each excluded robot once, as excluded (the allocation saw it as not
    in its view: it is alive, but the health judge kept it out)."""
    out = [(r, EXCLUDED if r in excluded and why == NOT_IN_VIEW else why) for r, why in ruled_out]
    listed = {r for r, _ in out}
    return tuple(out + [(r, EXCLUDED) for r in excluded if r not in listed])


def _reason_text(reason: Reason, plan: Plan | None) -> str:
    """What the allocator allocated for, in a person's words."""
    if isinstance(reason, Deploy):
        return "deploy"
    if isinstance(reason, Reissue):
        return reason.why
    if isinstance(reason, Recover):
        return f"recovery: {reason.action} for {reason.instance} on {reason.robot}"
    active = None if plan is None else plan.active_of(reason.component)
    origin = "" if active is None else f" from {active.robot}"
    if isinstance(reason, Comply):
        return f"compliance: move {reason.component}{origin}: {reason.why}"
    return f"move {reason.component}{origin}" + (f" to {reason.to}" if reason.to else "")


def _ask(reason: Reason, plan: Plan | None, ctx: Context) -> _Ask | Infeasible:
    state, held = ctx.state, ctx.held
    if isinstance(reason, Deploy):
        previous = plan if plan is not None and plan.system is not None else None
        return _Ask(reason.system, cluster_view(state, reason.origin), previous)
    if isinstance(reason, Reissue):
        assert plan is not None
        if not reason.recovery:
            return _Ask(plan.system, cluster_view(state, None), plan)
        return _Ask(
            plan.system, cluster_view(state, None, ctx.excluded), plan, {}, recovery=True, held=held
        )
    if isinstance(reason, Recover):
        comp = reason.component
        if plan is None or plan.system is None:
            return Infeasible(comp, (), 0)
        if all(c.name != comp for c in plan.system.components):
            raise LookupError(f"no component {comp!r} in the deployed system")
        if reason.action == "standby_same_robot":
            previous, avoid = swap_to_standby(plan, comp, reason.robot), {}
        else:
            previous, avoid = plan, {comp: {reason.robot}}
        view = cluster_view(state, None, ctx.excluded)
        return _Ask(plan.system, view, previous, avoid, recovery=True, held=held - {comp})
    to = reason.to if isinstance(reason, Move) else None
    inputs = move_inputs(plan, reason.component, to, state.alive)
    view = cluster_view(state, None, ctx.excluded)
    return _Ask(inputs.system, view, inputs.previous, inputs.avoid, held=held - {reason.component})


def _logs(reason: Reason, old: Plan | None, new: Plan, epoch: int) -> list[Log]:
    if isinstance(reason, Deploy):
        system = None if reason.system is None else reason.system.name
        return [Log(EventKind.ALLOCATION, {"reason": "deploy", "epoch": epoch, "system": system})]
    assert old is not None
    moved = moved_components(old, new)
    if isinstance(reason, Reissue):
        logs = [Log(EventKind.ALLOCATION, {"reason": reason.why, "epoch": epoch})]
        if reason.recovery and moved:
            logs.append(Log(EventKind.RECOVERY_MOVE, {"reason": reason.why, "moved": moved}))
        return logs
    if isinstance(reason, Recover):
        why = f"{reason.action} for {reason.instance} on {reason.robot}"
        return [Log(EventKind.RECOVERY_MOVE, {"reason": why, "moved": moved})]
    active = old.active_of(reason.component)
    origin = "" if active is None else active.robot
    if isinstance(reason, Comply):
        why = f"compliance: {reason.component} off {origin}: {reason.why}"
        return [
            Log(EventKind.ALLOCATION, {"reason": why, "epoch": epoch}),
            Log(EventKind.COMPLIANCE_MOVE, {"reason": why, "moved": moved}),
        ]
    why = f"move {reason.component} from {origin}" + (f" to {reason.to}" if reason.to else "")
    return [
        Log(EventKind.ALLOCATION, {"reason": why, "epoch": epoch}),
        Log(EventKind.MOVE, {"reason": why, "moved": moved}),
    ]


def with_origins(new: Plan, old: Plan | None, state: ClusterState) -> Plan:
    """`new` with the origins of `old` it still needs (the component is not back on its robot),
    and one for each `keep_original` active it moves off a robot that is gone."""
    if new.system is None or old is None or old.system is None:
        return replace(new, origins=())
    names = {c.name for c in new.system.components}
    same = old.system.digest() == new.system.digest()  # a new system starts afresh
    origins = dict(old.origins) if same else {}
    for comp, (src, _) in moved_components(old, new).items():
        if src not in state.alive and new.system.component(comp).disconnect.reconcile == (
            "keep_original"
        ):
            origins.setdefault(comp, src)
    kept = {}
    for comp, robot in origins.items():
        active = new.active_of(comp)
        if comp in names and (active is None or active.robot != robot):
            kept[comp] = robot
    return replace(new, origins=tuple(sorted(kept.items())))


def moved_components(old: Plan, new: Plan) -> dict[str, list[str]]:
    """component -> [from robot, to robot] for every active instance that changed robot."""
    out = {}
    for p in new.placements:
        if p.role != InstanceRole.ACTIVE:
            continue
        before = old.active_of(p.component)
        if before is not None and before.robot != p.robot:
            out[p.component] = [before.robot, p.robot]
    return out
