"""The coordinator's one call into the pure allocation core (`sdrpeer.alloc`).

How it works: `place` runs `allocate` with the allocator's epoch and the next plan version and
returns either the new `Plan` or the `Infeasible` report (never a partial plan).
"""

from __future__ import annotations

from sdrpeer.alloc.core import allocate
from sdrpeer.alloc.result import Infeasible
from sdrpeer.alloc.view import ClusterView
from sdrpeer.plan import Plan
from sdrpeer.system.model import SystemDef

__all__ = ["Infeasible", "place"]


def place(
    system: SystemDef,
    view: ClusterView,
    *,
    epoch: int,
    version: int,
    allocator: str,
    previous: Plan | None,
) -> Plan | Infeasible:
    """A plan for `system` on the robots in `view`, or why there is none."""
    result = allocate(
        system, view, epoch=epoch, version=version, allocator=allocator, previous=previous
    )
    if result.plan is not None:
        return result.plan
    assert result.infeasible is not None
    return result.infeasible
