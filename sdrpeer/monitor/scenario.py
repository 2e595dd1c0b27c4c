"""Scenario files: how virtual robots' hardware facts change over time.

How it works: a scenario is a list of steps, each at a time `at` (seconds from the scenario's
start) for one robot:

    steps:
      - {at: 10s,  robot: robot-2, set: {drain: 2%/min}}            # jump (any settable field)
      - {at: 20s,  robot: robot-3, move: {to: [5, 3], speed: 0.5m/s}} # straight line
      - {at: 107s, robot: robot-1, ramp: {rssi: -55dBm, over: 5s}}   # linear (rssi, memory)

Per (robot, field) the steps form a timeline sorted by `at` (file order breaks ties); a step
replaces whatever earlier step on that field is still running, and a ramp or move starts from
the value the field has at its `at` — from earlier steps, else from the robot's file (which is
why ramps and moves need the robot files). `changes_for(robot, t_prev, t_now)` is pure: the
`VirtualRobot.set` changes for fields that some step touches in (t_prev, t_now], each with its
value at t_now (interpolated for ramps and moves). Pass `-math.inf` as t_prev on the first call.
Live changes made through the API are not seen by the scenario: the next step overrides them.

Lab steps act on robots from outside, so no agent runs them: the lab that started the agents
does (`sdrpeer.lab.script`), at the same times:

      - {at: 30s, robot: robot-2, agent: kill}       # SIGKILL: the robot dies with its hosts
      - {at: 45s, robot: robot-2, agent: restart}    # the same agent again (data dir, key)
      - {at: 50s, robot: robot-4, agent: stop}       # SIGTERM: a graceful leave
      - {at: 60s, partition: [[robot-1, robot-2], [robot-3, robot-4]]}   # real packet drops
      - {at: 80s, heal: true}                         # no partition, no fault

`lab_steps()` lists them in time order; `changes_for` never returns anything for them.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from sdrpeer import units
from sdrpeer.errors import ScenarioError, shown
from sdrpeer.monitor.virtual import SETTABLE, RobotFile, parse_name, parse_position
from sdrpeer.yamlfile import YamlFile, line_of

RAMPABLE = ("rssi", "memory")
"""Fields a ramp may change."""
AGENT_ACTIONS = ("kill", "stop", "restart")
"""What an `agent:` step does to a robot's agent: SIGKILL, SIGTERM, start it again."""
LAB_KINDS = ("agent", "partition", "heal")
"""Step kinds the lab carries out (the agents never do)."""
_KINDS = ("set", "ramp", "move", *LAB_KINDS)


@dataclass(frozen=True, slots=True)
class Step:
    """One scenario step: at `at` s, `kind` ("set", "ramp" or "move") changes `values`; a lab
    step ("agent", "partition", "heal") acts on a robot's agent or on the lab's network."""

    at: float
    robot: str
    """The robot concerned ("" for a partition or a heal: the whole lab)."""
    kind: str
    values: dict[str, Any]
    """Field -> target value (for a move: {"pos": (x, y)}; an agent step: {"agent": "kill"};
    a partition: {"groups": (("robot-1", "robot-2"), ("robot-3",))}; a heal: {})."""
    over: float = 0.0
    """Ramp duration in seconds."""
    speed: float = 0.0
    """Move speed in metres per second."""
    line: int = 0
    """Line of the step in its file (for errors)."""


@dataclass(frozen=True, slots=True)
class _Segment:
    """A stretch of one field's timeline: from `start` at `at` to `target` at `end`."""

    at: float
    end: float
    start: Any
    target: Any

    def value(self, t: float) -> Any:
        """The field's value at t >= at."""
        if t >= self.end:
            return self.target
        f = (t - self.at) / (self.end - self.at)
        if isinstance(self.target, tuple):
            return tuple(a + (b - a) * f for a, b in zip(self.start, self.target, strict=True))
        mid = self.start + (self.target - self.start) * f
        return round(mid) if isinstance(self.target, int) else mid


@dataclass
class Scenario:
    """A validated scenario, with each robot's field timelines computed up front."""

    steps: list[Step]
    initial: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    """Robot -> field -> value before the scenario (from robot files: pos, rssi, memory)."""
    name: str = "<scenario>"
    """File name used in errors."""
    _timelines: dict[tuple[str, str], list[_Segment]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._timelines = {}
        for step in sorted(self.steps, key=lambda s: s.at):
            if step.kind in LAB_KINDS:
                continue
            for key, target in step.values.items():
                self._add(step, key, target)

    def _add(self, step: Step, key: str, target: Any) -> None:
        """Append a step's change of one field to that field's timeline."""
        segments = self._timelines.setdefault((step.robot, key), [])
        if step.kind == "set":
            segments.append(_Segment(step.at, step.at, target, target))
            return
        start = segments[-1].value(step.at) if segments else None
        if start is None:
            start = self.initial.get(step.robot, {}).get(key)
        if start is None:
            where = "move" if step.kind == "move" else f"ramp.{key}"
            raise ScenarioError(
                f"{self.name}:{step.line}: field '{where}': {step.robot} has no {key} to "
                f"start from (give it in the robot file or set it in an earlier step)"
            )
        moving = step.kind == "move"
        duration = math.dist(start, target) / step.speed if moving else step.over
        segments.append(_Segment(step.at, step.at + duration, start, target))

    @classmethod
    def load(
        cls, path: Path | str, robots: Iterable[RobotFile] | None = None, *, fleet: bool = False
    ) -> Scenario:
        """Read and validate a scenario file (robot names checked if robot files are given)."""
        return _build(YamlFile.read(path, ScenarioError), robots, fleet=fleet)

    @classmethod
    def parse(
        cls, text: str, filename: str = "<scenario>", robots: Iterable[RobotFile] | None = None
    ) -> Scenario:
        """Validate scenario text; `filename` is used in errors."""
        return _build(YamlFile(text, filename, ScenarioError), robots)

    def robots(self) -> set[str]:
        """Names of the robots the scenario changes."""
        out = {s.robot for s in self.steps if s.robot}
        for s in self.steps:
            out.update(r for group in s.values.get("groups", ()) for r in group)
        return out

    def lab_steps(self) -> list[Step]:
        """The steps the lab carries out (agent, partition, heal), by time (file order breaks
        ties)."""
        return sorted((s for s in self.steps if s.kind in LAB_KINDS), key=lambda s: s.at)

    def end(self) -> float:
        """Time at which the last step is complete."""
        return max((seg[-1].end for seg in self._timelines.values() if seg), default=0.0)

    def value_at(self, robot: str, key: str, t: float) -> Any:
        """The scenario's value of a robot's field at t, or None before any step touches it."""
        segments = self._timelines.get((robot, key), [])
        i = bisect.bisect_right([s.at for s in segments], t)
        return segments[i - 1].value(t) if i else None

    def changes_for(self, robot: str, t_prev: float, t_now: float) -> dict[str, Any]:
        """`set()` changes for `robot` from steps active in (t_prev, t_now], valued at t_now."""
        changes: dict[str, Any] = {}
        for (name, key), segments in self._timelines.items():
            if name == robot and any(s.at <= t_now and s.end > t_prev for s in segments):
                changes[key] = self.value_at(robot, key, t_now)
        return changes


def _step(doc: YamlFile, node: yaml.Node, known: set[str] | None) -> Step:
    """Validate one step mapping."""
    keys = doc.mapping(node, None, ("at", "robot", *_KINDS), ("at",))
    at = doc.parse(keys["at"], "at", units.parse_duration)
    actions = [k for k in _KINDS if k in keys]
    if len(actions) != 1:
        doc.fail(node, None, f"a step needs exactly one of {', '.join(_KINDS)}")
    kind = actions[0]
    body = keys[kind]
    line = line_of(node)
    if kind in ("partition", "heal"):
        if "robot" in keys:
            doc.fail(keys["robot"], "robot", f"a {kind} step is for the whole lab: no robot")
        return _network_step(doc, kind, body, at, line=line, known=known)
    if "robot" not in keys:
        doc.fail(node, "robot", "missing (required)")
    robot = doc.parse(keys["robot"], "robot", parse_name)
    if known is not None and robot not in known:
        doc.fail(
            keys["robot"], "robot", f"unknown robot {robot!r} (known: {', '.join(sorted(known))})"
        )
    if kind == "agent":
        action = doc.value(body)
        if action not in AGENT_ACTIONS:
            doc.fail(body, "agent", f"expected one of {', '.join(AGENT_ACTIONS)}, got {action!r}")
        return Step(at, robot, kind, {"agent": action}, line=line)
    if kind == "set":
        fields = doc.mapping(body, "set", sorted(SETTABLE))
        if not fields:
            doc.fail(body, "set", "nothing to set")
        values = {k: doc.parse(v, f"set.{k}", SETTABLE[k]) for k, v in fields.items()}
        return Step(at, robot, kind, values, line=line)
    if kind == "ramp":
        fields = doc.mapping(body, "ramp", (*RAMPABLE, "over"), ("over",))
        over = doc.parse(fields.pop("over"), "ramp.over", _positive(units.parse_duration, "5s"))
        if not fields:
            doc.fail(body, "ramp", f"nothing to ramp (rampable: {', '.join(RAMPABLE)})")
        values = {k: doc.parse(v, f"ramp.{k}", SETTABLE[k]) for k, v in fields.items()}
        return Step(at, robot, kind, values, over=over, line=line)
    fields = doc.mapping(body, "move", ("to", "speed"), ("to", "speed"))
    to = doc.parse(fields["to"], "move.to", parse_position)
    speed = doc.parse(fields["speed"], "move.speed", _positive(units.parse_speed, "0.5m/s"))
    return Step(at, robot, kind, {"pos": to}, speed=speed, line=line)


def _network_step(
    doc: YamlFile, kind: str, body: yaml.Node, at: float, *, line: int, known: set[str] | None
) -> Step:
    """A `partition: [[A, B], [C]]` or `heal: true` step."""
    if kind == "heal":
        if doc.value(body) is not True:
            doc.fail(body, "heal", "write heal: true")
        return Step(at, "", kind, {}, line=line)
    groups: list[tuple[str, ...]] = []
    seen: set[str] = set()
    for k, group in enumerate(doc.sequence(body, "partition")):
        names = []
        for item in doc.sequence(group, f"partition[{k}]"):
            name = doc.parse(item, f"partition[{k}]", parse_name)
            if known is not None and name not in known:
                doc.fail(item, f"partition[{k}]", f"unknown robot {name!r}")
            if name in seen:
                doc.fail(item, f"partition[{k}]", f"{name} is in two groups")
            seen.add(name)
            names.append(name)
        if not names:
            doc.fail(group, f"partition[{k}]", "an empty group")
        groups.append(tuple(names))
    if len(groups) < 2:
        doc.fail(body, "partition", "needs at least two groups: [[robot-1, robot-2], [robot-3]]")
    return Step(at, "", kind, {"groups": tuple(groups)}, line=line)


def _positive(parser: Callable[[object], float], example: str) -> Callable[[object], float]:
    """A parser that also refuses zero."""

    def parse(value: object) -> float:
        result = parser(value)
        if result <= 0:
            raise ValueError(f"expected a value above zero such as {example}, got {shown(value)}")
        return result

    return parse


def _build(doc: YamlFile, robots: Iterable[RobotFile] | None, *, fleet: bool = False) -> Scenario:
    """Validate a composed scenario document. `fleet`: one file for every robot of a fleet,
    read by each robot's agent with only its own robot file: other robots' steps are accepted
    unchecked (their own agents check them)."""
    files = {r.name: r for r in robots} if robots is not None else None
    top = doc.mapping(doc.root, None, ("steps", "description"), ("steps",))
    known = set(files) if files is not None and not fleet else None
    steps = [_step(doc, node, known) for node in doc.sequence(top["steps"], "steps")]
    initial = {
        name: {"pos": f.position, "rssi": f.rssi, "memory": f.memory}
        for name, f in (files or {}).items()
    }
    return Scenario(steps, initial, doc.name)
