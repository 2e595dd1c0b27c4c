"""The plan one robot holds, fenced by the allocator's (epoch, name), kept across restarts.

How it works: `offer(plan)` (pure: the deployment core calls it) accepts a plan only when its
key `(epoch, allocator, version)` is larger than the held plan's and the election fence
(`sdrpeer.election.fence.Fence`, raised by `see_claim` to every allocator claim this robot hears
of) admits its `(epoch, allocator)`: a plan from a stale allocator is refused and counted, so it
cannot undo a newer one. The shell writes an accepted plan to `DATA_DIR/plan.json` with `save()`
(atomically); it is read back when the agent starts, so a restarted robot still knows the system
and can give it to a new allocator. `info()` is what the robot gossips about it.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from sdrpeer.election.fence import Fence
from sdrpeer.plan import Plan, plan_from_json
from sdrpeer.record.robot import PlanInfo
from sdrpeer.system.model import DigestMemo, json_digest

log = logging.getLogger(__name__)


def plan_digest(plan: Plan) -> str:
    """A short hash of a plan's content (system and placements); computed once per plan object
    (every record published carries it)."""
    return _DIGESTS.get(plan, lambda: json_digest(plan.to_json()))


_DIGESTS = DigestMemo()


class PlanStore:
    """One robot's current plan and the fence that guards it."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self.plan: Plan | None = None
        self.fence = Fence()
        self._digest = ""
        if path is not None and path.is_file():
            self._load(path)

    @property
    def highest_epoch(self) -> int:
        """The highest allocator epoch this robot has seen (plans or election)."""
        return self.fence.epoch

    @property
    def refused_stale(self) -> int:
        """Plans refused because they were older than what this robot holds or has seen."""
        return self.fence.refused

    def _load(self, path: Path) -> None:
        try:
            plan = plan_from_json(json.loads(path.read_text()))
        except (OSError, ValueError) as e:
            log.warning("%s: ignoring the saved plan: %s", path, e)
            return
        self.plan = plan
        self.fence.raise_to(plan.epoch, plan.allocator)

    def see_claim(self, epoch: int, allocator: str) -> None:
        """The election heard of an allocator claiming at this epoch."""
        self.fence.raise_to(epoch, allocator)

    def accepts(self, key: tuple[int, str, int]) -> bool:
        """Whether a plan with this key would be taken (without taking it)."""
        epoch, allocator, _ = key
        if not self.fence.accepts(epoch, allocator):
            return False
        return self.plan is None or key > self.plan.key

    def offer(self, plan: Plan) -> bool:
        """Take `plan` if it is newer than ours and not from a fenced-off allocator."""
        if not self.accepts(plan.key):
            self.fence.refused += 1
            return False
        self.fence.admit(plan.epoch, plan.allocator)
        self.plan = plan
        self._digest = ""
        return True

    def info(self) -> PlanInfo | None:
        """What the gossip record says about the plan held."""
        if self.plan is None:
            return None
        p = self.plan
        if not self._digest:  # computed once per plan held, when first gossiped
            self._digest = plan_digest(p)
        return PlanInfo(p.epoch, p.version, self._digest, p.allocator)

    def save(self) -> None:
        """Write the plan held to `path` (atomically; nothing without a path or a plan)."""
        plan = self.plan
        if self.path is None or plan is None:
            return
        tmp = self.path.with_suffix(".tmp")
        try:
            tmp.write_text(json.dumps(plan.to_json(), default=str))
            tmp.replace(self.path)
        except OSError as e:
            log.warning("%s: cannot save the plan: %s", self.path, e)
