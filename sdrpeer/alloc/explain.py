"""The allocator's explanation of one allocation: why each instance went where it went.

How it works: the allocation core (`core.py`) tells an `Explainer` what it does as it does it:
`tried(instance, robot, why)` for every robot it tried and ruled out (the first constraint that
robot failed, as `Feasibility.reason` says it), `placed(...)` when a robot takes an instance (with
how: kept, pinned, a standby promoted, `prefer`, the strategy's order...), `left_out(...)` when a
standby finds no robot and the allocation may go on without it (with every robot's reason). Each
becomes a `Why` (`sdrpeer.plan`), returned in the plan next to the placements: nothing is
recomputed afterwards, so the explanation is what the allocation did, not a guess at it.

What a `Why` lists as checked on its robot is the constraints that passed there: the launch
policy, the enabled Table I constraints (for a cold standby only those that apply to it) and, for
each connected component whose active is on another robot, the enabled Table II constraints of
that link. Under the objective strategy the score the ranker ranked each robot tried by is kept
too (`Ranker.score`: the weighted terms, the instance's own need left out as the ranker leaves it
out; it shifts every robot alike). Pure: no clock, no I/O; at most `MAX_RULED_OUT` robots
are listed per instance, the rest counted, so a plan stays small in a large fleet.
"""

from __future__ import annotations

from collections.abc import Sequence

from sdrpeer.alloc.feasibility import Feasibility
from sdrpeer.alloc.strategies import Peer, Ranker
from sdrpeer.alloc.view import RobotView
from sdrpeer.plan import MAX_RULED_OUT, Why
from sdrpeer.system.model import ComponentDef
from sdrpeer.vocabulary import InstanceRole


class Explainer:
    """Collects the `Why` of every instance of one allocation (used once)."""

    def __init__(self, robots: tuple[RobotView, ...], check: Feasibility, ranker: Ranker) -> None:
        self.robots = robots
        self.check = check
        self.ranker = ranker
        self._tried: dict[str, dict[int, str]] = {}
        """Instance -> robot index -> why it was ruled out, in the order tried."""
        self.whys: list[Why] = []

    def tried(self, instance: str, robot: int, why: str) -> None:
        """Robot `robot` was tried for `instance` and ruled out by `why`."""
        self._tried.setdefault(instance, {}).setdefault(robot, why)

    def carry(self, old: str, new: str) -> None:
        """The robots tried for instance `old` were tried for `new` (a standby promoted to be
        the active takes the active's place under its own name)."""
        tried = self._tried.pop(old, {})
        for robot, why in tried.items():
            self.tried(new, robot, why)

    def placed(
        self,
        comp: ComponentDef,
        instance: str,
        role: InstanceRole,
        robot: int,
        *,
        cold: bool,
        how: str,
        peers: Sequence[Peer],
    ) -> None:
        """`robot` took the instance (`how`: see `sdrpeer.plan.HOW`)."""
        trail = [(i, w) for i, w in self._tried.pop(instance, {}).items() if i != robot]
        scored = [i for i, _ in trail[:MAX_RULED_OUT]] + [robot]
        self.whys.append(
            Why(
                component=comp.name,
                instance=instance,
                role=role,
                robot=self.robots[robot].name,
                how=how,
                checked=self._checked(comp, cold, robot, peers),
                ruled_out=tuple((self.robots[i].name, w) for i, w in trail[:MAX_RULED_OUT]),
                more_ruled_out=max(0, len(trail) - MAX_RULED_OUT),
                scores=self._scores(comp, peers, scored),
            )
        )

    def held(self, comp: ComponentDef, instance: str, role: InstanceRole, robot: str) -> None:
        """The disconnect policy keeps the instance on `robot` (its robot is lost)."""
        self.whys.append(Why(comp.name, instance, role, robot, "held"))

    def left_out(
        self, comp: ComponentDef, instance: str, role: InstanceRole, reasons: list[tuple[str, str]]
    ) -> None:
        """No robot took the instance and the allocation goes on without it."""
        self._tried.pop(instance, None)
        self.whys.append(
            Why(
                component=comp.name,
                instance=instance,
                role=role,
                robot=None,
                how="left_out",
                ruled_out=tuple(reasons[:MAX_RULED_OUT]),
                more_ruled_out=max(0, len(reasons) - MAX_RULED_OUT),
            )
        )

    def _checked(
        self, comp: ComponentDef, cold: bool, robot: int, peers: Sequence[Peer]
    ) -> tuple[str, ...]:
        """The constraints robot `robot` passed for this instance (module docstring)."""
        check = self.check
        out = ["launch"]
        statics = [c.name for c in check.static_cs if c.cold or not cold]
        out += statics + [c.name for c in (check.cold_cs if cold else check.hot_cs)]
        links = ", ".join(c.name for c in check.link_cs)
        for p in peers:
            if p.robot != robot and links:
                out.append(f"link to {p.component} on {self.robots[p.robot].name}: {links}")
        if comp.name in check.avoid:
            out.append(f"avoid: not {', '.join(sorted(check.avoid[comp.name]))}")
        return tuple(dict.fromkeys(out))

    def _scores(
        self, comp: ComponentDef, peers: Sequence[Peer], robots: list[int]
    ) -> tuple[tuple[str, float], ...]:
        """(robot, the ranker's score) for `robots` (nothing under a strategy without scores)."""
        out = []
        for i in robots:
            score = self.ranker.score(comp, peers, i)
            if score is None:
                return ()
            out.append((self.robots[i].name, round(score, 4)))
        return tuple(out)
