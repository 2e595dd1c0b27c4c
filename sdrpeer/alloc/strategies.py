"""Placement strategies: in which order to try the robots for one instance.

How it works: the allocation core asks a strategy for a `Ranker` once per allocation; for each
instance it asks the ranker for robot indices in the order to try them and takes the first one
that passes every constraint. Robots are indexed in first-fit order: the robot that received the
system (`ClusterView.origin`) first, then the others in view order. `prefer`, pins and reuse of
running instances are handled by the core before the ranker is consulted.

- `first_fit` (the paper's first algorithm): that order as it is.
- `objective` (the paper's second): the highest weighted score first (`scores.py`); ties keep
  first-fit order. Per robot, the terms that depend only on the robot and on what the plan put
  on it are kept in `base` and updated when an instance lands there (`placed`); per instance
  only closeness and local traffic are added, from memoised per-robot closeness rows. The best
  robot is found with one `max`; the rest are sorted only if it is ruled out.

Strategies are entry points of `sdrpeer.strategies`; `STRATEGIES.register` adds one in-process.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from sdrpeer.alloc.constraints import RobotLoad
from sdrpeer.alloc.scores import (
    DEFAULT_WEIGHTS,
    UNKNOWN_CLOSENESS,
    battery_score,
    closeness_score,
    load_score,
    mem_score,
    rssi_score,
    traffic_local_score,
)
from sdrpeer.alloc.view import RobotView
from sdrpeer.errors import ConfigError
from sdrpeer.plugins.registry import Registry
from sdrpeer.system.model import AllocationDef, ComponentDef


@dataclass(frozen=True, slots=True)
class Peer:
    """A connected component whose active instance is already placed."""

    robot: int
    """Index of its robot."""
    traffic: float
    """Bytes/s between it and the instance being placed (0 when unknown)."""
    component: str


@dataclass(frozen=True, slots=True)
class Context:
    """What a ranker may read: the robots in first-fit order and the plan's load on each."""

    robots: tuple[RobotView, ...]
    loads: tuple[RobotLoad, ...]
    """Parallel to `robots`; the core updates them as instances land."""
    allocation: AllocationDef


class Ranker:
    """Orders robots for one allocation; told when an instance lands on a robot."""

    def order(self, component: ComponentDef, peers: Sequence[Peer]) -> Iterator[int]:
        """Robot indices in the order to try them for an instance of `component`."""
        raise NotImplementedError

    def placed(self, robot: int) -> None:
        """An instance was placed on robot `robot` (its load changed)."""

    def score(self, component: ComponentDef, peers: Sequence[Peer], robot: int) -> float | None:
        """The score `order` ranks robot `robot` by for this instance now (None: the strategy
        does not score; the allocation's explanation shows it)."""
        return None


class Strategy:
    """A placement strategy plugin."""

    name = ""

    def ranker(self, ctx: Context) -> Ranker:
        """A ranker for one allocation over `ctx`."""
        raise NotImplementedError


class _InOrder(Ranker):
    def __init__(self, n: int) -> None:
        self.n = n

    def order(self, component: ComponentDef, peers: Sequence[Peer]) -> Iterator[int]:
        return iter(range(self.n))


class FirstFit(Strategy):
    """The first robot, in first-fit order, that satisfies the constraints."""

    name = "first_fit"

    def ranker(self, ctx: Context) -> Ranker:
        return _InOrder(len(ctx.robots))


def weights_of(allocation: AllocationDef, known: dict[str, float]) -> dict[str, float]:
    """`known` defaults overridden by the system's weights; ConfigError on an unknown term."""
    weights = dict(known)
    for term, w in allocation.weights:
        if term not in known:
            raise ConfigError(
                f"allocation.weights: unknown term {term!r} (known: {', '.join(sorted(known))})"
            )
        weights[term] = w
    return weights


def distance_scale(ctx: Context) -> float:
    """Metres at which closeness reaches 0: the distance threshold, else the positions' spread."""
    limit = ctx.allocation.thresholds.distance_below_m
    if limit is not None:
        return limit
    known = [r.metrics.pos for r in ctx.robots if r.metrics.pos is not None]
    if len(known) < 2:
        return 1.0
    xs = [p[0] for p in known]
    ys = [p[1] for p in known]
    return max(1.0, math.hypot(max(xs) - min(xs), max(ys) - min(ys)))


class Objective(Strategy):
    """The feasible robot with the highest weighted score (see `scores.py`)."""

    name = "objective"
    terms = DEFAULT_WEIGHTS

    def ranker(self, ctx: Context) -> Ranker:
        return _ObjectiveRanker(ctx, weights_of(ctx.allocation, self.terms))

    def terms_for(
        self, ctx: Context, component: ComponentDef, peers: Sequence[Peer], robot: int
    ) -> dict[str, float]:
        """Every term (unweighted) for placing `component` on robot index `robot` (exact form)."""
        r = ctx.robots[robot]
        load = ctx.loads[robot]
        m = r.metrics
        need = component.requires
        scale = max((x.metrics.mem_total for x in ctx.robots), default=0)
        dscale = distance_scale(ctx)
        close = [closeness_score(_distance(r, ctx.robots[p.robot]), dscale) for p in peers]
        total = sum(p.traffic for p in peers)
        local = sum(p.traffic for p in peers if p.robot == robot)
        return {
            "mem_free": mem_score(m.mem_free - load.mem_bytes - need.mem_bytes, scale),
            "battery": battery_score(m.battery_pct),
            "rssi": rssi_score(m.rssi_dbm),
            "distance": sum(close) / len(close) if close else UNKNOWN_CLOSENESS,
            "traffic_local": traffic_local_score(local, total),
            "load": load_score(m.cpu_pct + load.cpu_pct + need.cpu_pct),
        }


def _distance(a: RobotView, b: RobotView) -> float | None:
    """0 for the same robot (even without a position), else `a.distance_to(b)`."""
    return 0.0 if a is b else a.distance_to(b)


class _ObjectiveRanker(Ranker):
    def __init__(self, ctx: Context, weights: dict[str, float]) -> None:
        self.ctx = ctx
        self.w = weights
        self.mem_scale = max((r.metrics.mem_total for r in ctx.robots), default=0)
        self.dscale = distance_scale(ctx)
        self.static = [
            weights["battery"] * battery_score(r.metrics.battery_pct)
            + weights["rssi"] * rssi_score(r.metrics.rssi_dbm)
            for r in ctx.robots
        ]
        self.base = [self._base(i) for i in range(len(ctx.robots))]
        self.rows: dict[int, list[float]] = {}

    def _base(self, i: int) -> float:
        """The terms that do not depend on the instance (its own need left out, see scores.py)."""
        m = self.ctx.robots[i].metrics
        load = self.ctx.loads[i]
        return (
            self.static[i]
            + self.w["mem_free"] * mem_score(m.mem_free - load.mem_bytes, self.mem_scale)
            + self.w["load"] * load_score(m.cpu_pct + load.cpu_pct)
        )

    def placed(self, robot: int) -> None:
        self.base[robot] = self._base(robot)

    def score(self, component: ComponentDef, peers: Sequence[Peer], robot: int) -> float:
        """`order`'s score of one robot (the instance's own need left out: it shifts every
        robot alike), from the same memoised parts."""
        out = self.base[robot]
        wd = self.w["distance"]
        if peers and wd:
            out += wd / len(peers) * sum(self._row(p.robot)[robot] for p in peers)
        total = sum(p.traffic for p in peers)
        wt = self.w["traffic_local"]
        if total > 0 and wt:
            local = (p for p in peers if p.robot == robot)
            out += wt * sum(traffic_local_score(p.traffic, total) for p in local)
        return out

    def _row(self, q: int) -> list[float]:
        """Closeness of every robot to robot `q` (memoised)."""
        row = self.rows.get(q)
        if row is None:
            robots = self.ctx.robots
            here = robots[q]
            row = [closeness_score(_distance(here, r), self.dscale) for r in robots]
            self.rows[q] = row
        return row

    def order(self, component: ComponentDef, peers: Sequence[Peer]) -> Iterator[int]:
        scores = self.base
        wd = self.w["distance"]
        if peers and wd:
            close = self._row(peers[0].robot)
            for p in peers[1:]:
                close = list(map(operator.add, close, self._row(p.robot)))
            k = wd / len(peers)
            scores = [b + k * c for b, c in zip(scores, close, strict=True)]
        total = sum(p.traffic for p in peers)
        wt = self.w["traffic_local"]
        if total > 0 and wt:
            if scores is self.base:
                scores = list(scores)
            for p in peers:
                scores[p.robot] += wt * traffic_local_score(p.traffic, total)
        n = len(scores)
        best = max(range(n), key=scores.__getitem__, default=None)
        if best is None:
            return
        yield best
        for i in sorted(range(n), key=scores.__getitem__, reverse=True):
            if i != best:
                yield i


STRATEGIES: Registry[Strategy] = Registry("sdrpeer.strategies", (Strategy,), "allocation strategy")
"""Every strategy by name (entry points of `sdrpeer.strategies`, plus registered)."""
