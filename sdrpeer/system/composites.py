"""The `composites:` section: several components run by one host process in one ordered context.

How it works: each composite names its `members` (component entries: name, python target,
params, profile, requires) in execution order and its shared `execution` (`stepped`, or
`{periodic: HZ}`); members' own execution contexts are ignored. Each member is read like a
component of `components:` (sdrpeer.system.components: its class imported, its params converted
by the class), then the composite becomes one `ComponentDef` with the `composite` launcher, a
target of sdrpeer.launch.composite, params `Member.param`, and requirements the sum of its
members' (CPU, memory, and each OutPort's traffic as `Member.port`); its own `standby`, `pin`,
`prefer`, `watchdog` and `disconnect` are read as a component's. So the allocator, recovery and
the agents see one component. Its `ComponentEntry` carries the composite class built by
sdrpeer.sdk.composite, so connections are checked against `Member.port`. `Members` maps each
member's name to its composite, for `connections:` (`from: Cam.image` is `Vision`'s `Cam.image`).
Errors: a composite without members, a member name that is not an identifier, also a component,
or in two composites, a member that is not a python class.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml

from sdrpeer.errors import SdrpeerError, shown
from sdrpeer.launch.composite import CompositeTarget
from sdrpeer.sdk import Periodic, Stepped
from sdrpeer.sdk.composite import composite_class
from sdrpeer.system.classes import class_info
from sdrpeer.system.components import ComponentEntry, read_component
from sdrpeer.system.model import ComponentDef, Requirements
from sdrpeer.system.problems import MISSING, Problems

COMPOSITE_KEYS = (
    "name",
    "execution",
    "members",
    "standby",
    "pin",
    "prefer",
    "watchdog",
    "disconnect",
    "constraints",
)
MEMBER_KEYS = ("name", "launcher", "target", "params", "profile", "requires")
MAX_HZ = 10_000.0


@dataclass(frozen=True, slots=True)
class Member:
    """Where a member's ports are: its composite, and its own entry."""

    composite: str
    entry: ComponentEntry


def read_composites(
    p: Problems,
    node: yaml.Node | None,
    base_dir: Path,
    components: dict[str, ComponentEntry],
) -> tuple[dict[str, ComponentEntry], dict[str, Member]]:
    """Every composite by name, and every member by name (problems recorded in `p`)."""
    out: dict[str, ComponentEntry] = {}
    members: dict[str, Member] = {}
    known = (components, members)
    if node is None:
        return out, members
    for i, item in enumerate(p.sequence(node, "composites")):
        where = f"composites[{i}]"
        fields = p.mapping(item, where, COMPOSITE_KEYS, ("name", "members", "execution"))
        if fields is None:
            continue
        name, entry = _composite(p, fields, item, where, base_dir=base_dir, known=known)
        if not name:
            continue
        if name in out or name in components:
            first = (out.get(name) or components[name]).node.start_mark.line + 1
            p.add(fields["name"], f"{where}.name", f"{name!r} given twice (first at line {first})")
            continue
        out[name] = entry
    return out, members


def _composite(
    p: Problems,
    fields: dict[str, yaml.Node],
    node: yaml.Node,
    where: str,
    *,
    base_dir: Path,
    known: tuple[dict[str, ComponentEntry], dict[str, Member]],
) -> tuple[str, ComponentEntry]:
    errors_before = len(p.items)
    own = {k: v for k, v in fields.items() if k not in ("members", "execution")}
    name, entry = read_component(p, own, node, where, base_dir)  # name, standby, pin, ...
    hz = p.get(fields, "execution", where, _execution, MISSING)
    read = _members(p, fields.get("members"), f"{where}.members", base_dir=base_dir)
    parts = [(m, e) for m, e, f in read if _fits(p, (m, e, f), into=name, known=known)]
    if (
        len(p.items) != errors_before
        or entry.definition is None
        or hz is MISSING
        or name is MISSING  # a missing required key was recorded by `mapping` already
        or "members" not in fields
    ):
        return name, ComponentEntry(node, where, None, None)
    context = Stepped() if hz is None else Periodic(hz=hz)
    try:
        cls = composite_class(name, [(m, e.info.cls) for m, e in parts if e.info], context)
    except SdrpeerError as e:
        p.add(fields["members"], f"{where}.members", str(e))
        return name, ComponentEntry(node, where, None, None)
    defs = [(m, e.definition) for m, e in parts if e.definition is not None]
    definition = replace(
        entry.definition,
        launcher="composite",
        target=CompositeTarget(hz, tuple((m, str(d.target)) for m, d in defs)).text(),
        params=tuple(sorted((f"{m}.{k}", v) for m, d in defs for k, v in d.params)),
        requires=_sum(defs),
    )
    return name, ComponentEntry(node, where, class_info(cls), definition)


_Read = tuple[str, ComponentEntry, dict[str, yaml.Node]]
"""A member as read: its name, its entry, its fields."""


def _members(p: Problems, node: yaml.Node | None, where: str, *, base_dir: Path) -> list[_Read]:
    """A composite's members as read, in execution order."""
    out: list[_Read] = []
    items = p.sequence(node, where) if node is not None else []
    if isinstance(node, yaml.SequenceNode) and not items:
        p.add(node, where, "a composite needs at least one member")
    for i, item in enumerate(items):
        at = f"{where}[{i}]"
        fields = p.mapping(item, at, MEMBER_KEYS, ("name", "target"))
        if fields is None:
            continue
        name, entry = read_component(p, fields, item, at, base_dir, files=False)
        if name:
            out.append((name, entry, fields))
    return out


def _fits(
    p: Problems,
    read: _Read,
    *,
    into: str,
    known: tuple[dict[str, ComponentEntry], dict[str, Member]],
) -> bool:
    """Whether a member may join composite `into` (else recorded); if so it is recorded in
    `known[1]`."""
    components, members = known
    name, entry, fields = read
    at, name_node = f"{entry.where}.name", fields.get("name")
    problem = None
    if not name.isidentifier():
        problem = f"a member's name must be an identifier, got {name!r}"
    elif name in components:
        problem = f"{name!r} is also a component (line {_line(components[name])})"
    elif name in members:
        first = members[name]
        problem = f"{name!r} is already a member of {first.composite} (line {_line(first.entry)})"
    if problem is not None:
        p.add(name_node, at, problem)
        return False
    d = entry.definition
    if d is not None and d.launcher != "python":
        p.add(
            fields.get("launcher"),
            f"{entry.where}.launcher",
            f"a member runs in its composite's Python host: only 'python', got {d.launcher!r}",
        )
        return False
    members[name] = Member(into, entry)
    return True


def _line(entry: ComponentEntry) -> int:
    return int(entry.node.start_mark.line) + 1


def _execution(value: Any) -> float | None:
    """`stepped` (None) or `{periodic: HZ}`, 0 < HZ <= 10000 (the rate in Hz)."""
    if value == "stepped":
        return None
    if isinstance(value, dict) and set(value) == {"periodic"}:
        hz = value["periodic"]
        number = not isinstance(hz, bool) and isinstance(hz, int | float)
        if number and math.isfinite(hz) and 0 < hz <= MAX_HZ:
            return float(hz)
    raise ValueError(
        f"expected stepped or {{periodic: HZ}} with 0 < HZ <= 10000, got {shown(value)}"
    )


def _sum(defs: list[tuple[str, ComponentDef]]) -> Requirements:
    """The members' requirements added up; traffic by `Member.port`."""
    rates = {f"{m}.{port}": r for m, d in defs for port, r in d.requires.out_bytes_per_s}
    return Requirements(
        cpu_pct=sum(d.requires.cpu_pct for _, d in defs),
        mem_bytes=sum(d.requires.mem_bytes for _, d in defs),
        out_bytes_per_s=tuple(sorted(rates.items())),
    )
