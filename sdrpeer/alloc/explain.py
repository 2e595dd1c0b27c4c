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
out; it shifts every robot alike), for placements the strategy's order decided: the chosen
robot and the first `MAX_SCORED` tried before it. Pure: no clock, no I/O; at most
`MAX_RULED_OUT` robots are listed per instance, the rest counted, so a plan stays small in a
large fleet.
"""

from __future__ import annotations

from collections.abc import Sequence

from sdrpeer.alloc.feasibility import Feasibility
from sdrpeer.alloc.strategies import Peer, Ranker
from sdrpeer.alloc.view import RobotView
from sdrpeer.plan import MAX_RULED_OUT, Why
from sdrpeer.system.model import ComponentDef
from sdrpeer.vocabulary import InstanceRole

MAX_SCORED = 4
"""Robots tried before the chosen one whose scores are kept (the best ones: tried first)."""


class Explainer:
    """Collects the `Why` of every instance of one allocation (used once)."""

    def __init__(self, robots: tuple[RobotView, ...], check: Feasibility, ranker: Ranker) -> None:
        self.robots = robots
        self.check = check
        self.ranker = ranker
        self._robot_checked = {
            cold: tuple(
                dict.fromkeys(
                    ["launch"]
                    + [c.name for c in check.static_cs if c.cold or not cold]
                    + [c.name for c in (check.cold_cs if cold else check.hot_cs)]
                )
            )
            for cold in (False, True)
        }
        """The robot constraints a hot (False) or cold (True) instance's robot passed."""
        self._links = ", ".join(c.name for c in check.link_cs)
        """The link constraints every cross-robot connection passed."""
        self._tried: dict[str, list[tuple[int, str]]] = {}
        """Instance -> (robot index, why it was ruled out), in the order tried (a robot tried
        twice is listed once, with its first reason: see `_trail`)."""
        self.whys: list[Why] = []

    def tried(self, instance: str, robot: int, why: str) -> None:
        """Robot `robot` was tried for `instance` and ruled out by `why`."""
        trail = self._tried.get(instance)
        if trail is None:
            self._tried[instance] = [(robot, why)]
        else:
            trail.append((robot, why))

    def carry(self, old: str, new: str) -> None:
        """The robots tried for instance `old` were tried for `new` (a standby promoted to be
        the active takes the active's place under its own name)."""
        for robot, why in self._tried.pop(old, ()):
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
        trail = self._trail(instance, robot)
        ranked = how in ("ranked", "preferred")  # the strategy's order decided: show its scores
        scored = [i for i, _ in trail[:MAX_SCORED]] + [robot] if ranked else []
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

    def _trail(self, instance: str, robot: int | None) -> list[tuple[int, str]]:
        """The robots tried for `instance` but `robot`, each once, in the order first tried."""
        seen: dict[int, str] = {}
        for i, why in self._tried.pop(instance, ()):
            if i != robot:
                seen.setdefault(i, why)
        return list(seen.items())

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
        check, links = self.check, self._links
        out = self._robot_checked[cold]
        if links and any(p.robot != robot for p in peers):
            out += tuple(
                dict.fromkeys(
                    f"link to {p.component} on {self.robots[p.robot].name}: {links}"
                    for p in peers
                    if p.robot != robot
                )
            )
        if comp.name in check.avoid:
            out += (f"avoid: not {', '.join(sorted(check.avoid[comp.name]))}",)
        return out

    def _scores(
        self, comp: ComponentDef, peers: Sequence[Peer], robots: list[int]
    ) -> tuple[tuple[str, float], ...]:
        """(robot, the ranker's score) for `robots` (nothing under a strategy without scores)."""
        if not robots:
            return ()
        out = []
        for i in robots:
            score = self.ranker.score(comp, peers, i)
            if score is None:
                return ()
            out.append((self.robots[i].name, round(score, 4)))
        return tuple(out)
