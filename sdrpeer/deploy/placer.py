"""The coordinator's one call into the pure allocation core (`sdrpeer.alloc`).

How it works: `place` runs `allocate` with the allocator's epoch and the next plan version and
returns either the new `Plan` or the `Infeasible` report (never a partial plan).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import replace

from sdrpeer.alloc.core import allocate
from sdrpeer.alloc.result import Infeasible
from sdrpeer.alloc.view import ClusterView
from sdrpeer.plan import Plan
from sdrpeer.system.model import SystemDef

RECOVERY_MEMORY_CAUSE = "memory_shortage"


def relaxed_for_recovery(system: SystemDef) -> SystemDef:
    """`system` with the free-memory threshold of allocation (Table V) replaced by the level at
    which the recovery rules see a memory shortage (Table VI's 200MB; its clearing level if
    set): components moved by recovery may leave a robot below the allocation threshold, but
    must not cause a shortage there. Without a memory_shortage rule: only capacity."""
    level: float | None = None
    for rule in system.recovery.rules:
        if rule.cause == RECOVERY_MEMORY_CAUSE and rule.metric == "mem_free":
            level = rule.clear if rule.clear is not None else rule.threshold
    t = replace(
        system.allocation.thresholds, mem_free_above_bytes=None if level is None else int(level)
    )
    return replace(system, allocation=replace(system.allocation, thresholds=t))


__all__ = ["Infeasible", "place", "relaxed_for_recovery"]


def place(
    system: SystemDef,
    view: ClusterView,
    *,
    epoch: int,
    version: int,
    allocator: str,
    previous: Plan | None,
    avoid: Mapping[str, Collection[str]] | None = None,
    recovery: bool = False,
    held: Collection[str] = (),
) -> Plan | Infeasible:
    """A plan for `system` on the robots in `view`, or why there is none.

    `recovery`: components move because of a failure: the thresholds are `relaxed_for_recovery`
    and standbys are placed where they fit (the actives first: availability), the plan keeping
    the system as given. `held`: components kept where the previous plan has them (the
    disconnect policy: their robot is lost, and the fleet does not replace them yet)."""
    result = allocate(
        relaxed_for_recovery(system) if recovery else system,
        view,
        epoch=epoch,
        version=version,
        allocator=allocator,
        previous=previous,
        avoid=avoid,
        standbys_optional=recovery,
        held=held,
    )
    if result.plan is not None and recovery:
        return replace(result.plan, system=system)
    if result.plan is not None:
        return result.plan
    assert result.infeasible is not None
    return result.infeasible
