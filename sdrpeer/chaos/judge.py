"""The chaos soak's invariants, checked on every look at the fleet (pure: times passed in).

How it works: the runner looks at every robot four times a second and hands `Judge.observe` one
`Look`: per component, the robots where an instance of it is ACTIVE as the active one (each
robot's own word, from its instance manager), each robot's plan key, each agent's RSS, and
whether a partition is on. The judge keeps:
- **one active**: a component ACTIVE on two robots at once, while the network is whole, for longer
  than `fence_window_s` (1 s) is a violation. During a partition the judge lets it pass (the side
  cut off may keep its copy by policy; the clock starts at the heal, which the runner reports
  with `healed(t)`), but with the default
  disconnect policy (`sdrpeer.deploy.disconnect`) the side cut off has stood its actives down
  before the heal, so a heal finds one copy. The window covers a handover: the new copy is
  activated as the plan reaches its robot, the old one deactivated as it reaches its own. An
  episode's length is what the looks saw (from the first to the last look that found two
  actives: a lower bound, as fine as the looks are frequent; the report gives their spacing,
  `look_interval_s`). Every episode's length is kept (`double_active_s`) so the report shows how
  close the fleet came;
- **no plan lost**: a robot's plan key never goes backwards (plans are fenced and persisted, also
  across an agent restart), and at the end the plan still places every component;
- **memory bounded**: each agent's RSS stays below `rss_limit` bytes;
- **recovery**: a look where every component is ACTIVE on exactly one robot is *whole*; every
  fault started since the last whole look is recovered at this look (its recovery time is the
  difference); after the last fault ends, the first whole look must come within `converge_s`.
  A recovery is *isolated* when no other fault was on (from its start to its end, a kill_host
  being an instant) between the fault's start and its recovery, else *overlapping*; the report
  gives both apart.
`report()` is the soak's result: faults, recovery times, violations.
"""

from __future__ import annotations

import statistics
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Judge", "Look"]

PlanKey = tuple[int, str, int]


@dataclass(frozen=True, slots=True)
class Look:
    """One look at the fleet."""

    t: float
    actives: Mapping[str, frozenset[str]]
    """Component -> robots where its active instance is ACTIVE (components with none: empty)."""
    plans: Mapping[str, PlanKey | None] = field(default_factory=dict)
    """Robot -> the key of the plan it holds (robots that answered)."""
    rss: Mapping[str, int] = field(default_factory=dict)
    """Robot -> its agent's RSS in bytes."""
    partitioned: bool = False


def _pct(values: list[float], q: float) -> float | None:
    if not values:
        return None
    ordered = sorted(values)
    return round(ordered[min(len(ordered) - 1, int(q * len(ordered)))], 3)


def _figures(values: list[float]) -> dict[str, Any]:
    return {
        "n": len(values),
        "p50": _pct(values, 0.5),
        "p99": _pct(values, 0.99),
        "max": round(max(values), 3) if values else None,
        "mean": round(statistics.fmean(values), 3) if values else None,
    }


class Judge:
    """Checks the soak's invariants look by look."""

    def __init__(
        self,
        components: list[str],
        *,
        fence_window_s: float = 1.0,
        converge_s: float = 3.0,
        rss_limit: int = 200 * 1024 * 1024,
    ) -> None:
        self.components = components
        self.fence_window_s = fence_window_s
        self.converge_s = converge_s
        self.rss_limit = rss_limit
        self.violations: list[dict[str, Any]] = []
        self.faults: Counter[str] = Counter()
        self.recoveries: list[float] = []
        self.isolated: list[float] = []
        """Recovery times of faults with no other fault on meanwhile."""
        self._spans: list[tuple[float, float]] = []
        """(start, end) of every fault so far."""
        self.peak_rss: dict[str, int] = {}
        self.first_rss: dict[str, int] = {}
        self.converged_after: float | None = None
        self.double_active_s: list[float] = []
        """How long each episode of two actives lasted once the network was whole."""
        self._pending: list[tuple[float, int]] = []
        """(start, index in _spans) of the faults not recovered yet."""
        self._kinds: list[str] = []
        """The kind of every fault so far (by index in _spans)."""
        self.isolated_by_kind: dict[str, list[float]] = {}
        self._double: dict[str, float] = {}
        """Component -> when its two actives began to count: the first look that saw them, or the
        heal for two actives seen while the partition was on."""
        self._double_last: dict[str, float] = {}
        """Component -> the last look that saw two actives."""
        self._intervals: list[float] = []
        self._last_look: float | None = None
        self._reported_double: set[str] = set()
        self._plans: dict[str, PlanKey] = {}
        self._faults_over: float | None = None
        self._looks = 0

    def fault(self, t: float, kind: str, until: float | None = None) -> None:
        """A fault was injected at `t`, on until `until` (None: an instant, like a kill)."""
        self.faults[kind] += 1
        self._pending.append((t, len(self._spans)))
        self._kinds.append(kind)
        self._spans.append((t, t if until is None else max(t, until)))

    def faults_over(self, t: float) -> None:
        """The last fault ended at `t`: the fleet must converge within `converge_s`."""
        self._faults_over = t

    def healed(self, t: float) -> None:
        """The partition was healed at `t`: two actives seen while it was on count from `t`."""
        for comp in self._double:
            self._double[comp] = t

    def observe(self, look: Look) -> bool:
        """Check one look; True when it is whole (every component ACTIVE on exactly one robot)."""
        self._looks += 1
        if self._last_look is not None:
            self._intervals.append(look.t - self._last_look)
        self._last_look = look.t
        for comp in self.components:
            where = look.actives.get(comp, frozenset())
            if len(where) > 1 and look.partitioned:
                self._double[comp] = look.t  # allowed while cut: the clock starts at the heal
                self._double_last[comp] = look.t
            elif len(where) > 1:
                since = self._double.setdefault(comp, look.t)
                self._double_last[comp] = look.t
                if look.t - since > self.fence_window_s and comp not in self._reported_double:
                    self._reported_double.add(comp)
                    self._violate(
                        look.t, "two_active", comp, robots=sorted(where), for_s=look.t - since
                    )
            else:
                began = self._double.pop(comp) if comp in self._double else None
                last = self._double_last.pop(comp, None)
                if began is not None and last is not None and not look.partitioned:
                    self.double_active_s.append(round(last - began, 3))
                self._reported_double.discard(comp)
        for robot, key in look.plans.items():
            if key is None:
                continue
            before = self._plans.get(robot)
            if before is not None and key < before:
                self._violate(look.t, "plan_went_back", robot, was=list(before), now=list(key))
            self._plans[robot] = max(key, before) if before is not None else key
        for robot, rss in look.rss.items():
            self.first_rss.setdefault(robot, rss)
            self.peak_rss[robot] = max(rss, self.peak_rss.get(robot, 0))
            if rss > self.rss_limit:
                self._violate(look.t, "memory", robot, rss=rss)
        whole = all(len(look.actives.get(c, ())) == 1 for c in self.components)
        if whole:
            for t, k in self._pending:
                self.recoveries.append(look.t - t)
                others = (s for j, s in enumerate(self._spans) if j != k)
                if not any(start <= look.t and end >= t for start, end in others):
                    self.isolated.append(look.t - t)
                    self.isolated_by_kind.setdefault(self._kinds[k], []).append(
                        round(look.t - t, 3)
                    )
            self._pending.clear()
            if self._faults_over is not None and self.converged_after is None:
                self.converged_after = round(max(0.0, look.t - self._faults_over), 3)
                if self.converged_after > self.converge_s:
                    self._violate(look.t, "slow_convergence", "fleet", after_s=self.converged_after)
        return whole

    def final_plan(self, placed: Mapping[str, int]) -> None:
        """At the end: component -> active placements in the plan; every one must have one."""
        for comp in self.components:
            if placed.get(comp, 0) != 1:
                self._violate(0.0, "plan_lost", comp, active_placements=placed.get(comp, 0))

    def never_converged(self, t: float) -> None:
        """The soak ended without a whole look after the faults."""
        if self._faults_over is not None and self.converged_after is None:
            self._violate(t, "never_converged", "fleet", waited_s=round(t - self._faults_over, 3))

    def _violate(self, t: float, kind: str, subject: str, **detail: Any) -> None:
        self.violations.append({"t": round(t, 3), "kind": kind, "subject": subject, **detail})

    def report(self) -> dict[str, Any]:
        """The soak's figures."""
        growth = {r: self.peak_rss[r] - self.first_rss.get(r, 0) for r in self.peak_rss}
        overlapping = list((Counter(self.recoveries) - Counter(self.isolated)).elements())
        return {
            "faults": dict(sorted(self.faults.items())),
            "faults_total": sum(self.faults.values()),
            "recoveries": len(self.recoveries),
            "recovery_s": _figures(self.recoveries),
            "recovery_isolated_s": _figures(self.isolated),
            "recovery_isolated_by_kind": dict(sorted(self.isolated_by_kind.items())),
            "recovery_overlapping_s": _figures(overlapping),
            "converged_after_s": self.converged_after,
            "double_active_episodes": len(self.double_active_s),
            "double_active_max_s": max(self.double_active_s, default=None),
            "fence_window_s": self.fence_window_s,
            "looks": self._looks,
            "look_interval_s": {
                "p50": _pct(self._intervals, 0.5),
                "p99": _pct(self._intervals, 0.99),
                "max": round(max(self._intervals), 3) if self._intervals else None,
            },
            "agent_rss_peak_mib": round(max(self.peak_rss.values(), default=0) / 2**20, 1),
            "agent_rss_growth_mib": round(max(growth.values(), default=0) / 2**20, 1),
            "violations": self.violations,
        }
