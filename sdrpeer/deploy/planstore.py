"""The plan one robot holds, fenced by epoch, kept on disk across agent restarts.

How it works: `offer(plan)` accepts a plan only when its key `(epoch, version)` is larger than
the held plan's and its epoch is not below the highest allocator epoch this robot has seen
(`see_epoch`, fed by the election): a plan from a stale allocator is refused and counted, so it
cannot undo a newer one. An accepted plan is written to `DATA_DIR/plan.json` (atomically) and
read back when the agent starts, so a restarted robot still knows the system and can give it to a
new allocator. `info()` is what the robot gossips about it (epoch, version, digest).
"""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

from sdrpeer.plan import Plan, plan_from_json
from sdrpeer.record import PlanInfo

log = logging.getLogger(__name__)


def plan_digest(plan: Plan) -> str:
    """A short hash of a plan's content (system and placements)."""
    text = json.dumps(plan.to_json(), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class PlanStore:
    """One robot's current plan and the fence that guards it."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self.plan: Plan | None = None
        self.highest_epoch = 0
        """The highest allocator epoch this robot has seen (plans or election)."""
        self.refused_stale = 0
        """Plans refused because they came from an older epoch (or were not newer)."""
        self._digest = ""
        if path is not None and path.is_file():
            self._load(path)

    def _load(self, path: Path) -> None:
        try:
            plan = plan_from_json(json.loads(path.read_text()))
        except (OSError, ValueError) as e:
            log.warning("%s: ignoring the saved plan: %s", path, e)
            return
        self.plan = plan
        self._digest = plan_digest(plan)
        self.highest_epoch = plan.epoch

    def see_epoch(self, epoch: int) -> None:
        """The election announced an allocator with this epoch."""
        self.highest_epoch = max(self.highest_epoch, epoch)

    def accepts(self, epoch: int, version: int) -> bool:
        """Whether a plan with this key would be taken (without taking it)."""
        if epoch < self.highest_epoch:
            return False
        return self.plan is None or (epoch, version) > self.plan.key

    def offer(self, plan: Plan) -> bool:
        """Take `plan` if it is newer than ours and not from a fenced-off epoch."""
        if not self.accepts(plan.epoch, plan.version):
            self.refused_stale += 1
            return False
        self.plan = plan
        self._digest = plan_digest(plan)
        self.highest_epoch = max(self.highest_epoch, plan.epoch)
        self._save(plan)
        return True

    def info(self) -> PlanInfo | None:
        """What the gossip record says about the plan held."""
        if self.plan is None:
            return None
        return PlanInfo(self.plan.epoch, self.plan.version, self._digest)

    def _save(self, plan: Plan) -> None:
        if self.path is None:
            return
        tmp = self.path.with_suffix(".tmp")
        try:
            tmp.write_text(json.dumps(plan.to_json(), default=str))
            tmp.replace(self.path)
        except OSError as e:
            log.warning("%s: cannot save the plan: %s", self.path, e)
