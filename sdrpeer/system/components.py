"""The `components:` section: what to run, what it needs, where it may go.

How it works: each item is read field by field through `Problems`, so every wrong field of every
component is reported. Names, launchers and targets go through the same checks as an agent's
instance specs (sdrpeer.runtime.spec), so a system that loads can be deployed. For a `python`
target the class is imported (sdrpeer.system.classes) and the params are converted by the class's
own declarations. A `script` file and an `exec` program given by a relative path resolve against
the system file's directory and must exist (sdrpeer.system.paths). Requirements come from
`profile:` (a file written by `sdrpeer profile`, path relative to the system file) and/or
`requires:` (inline); an inline value wins over the profile's, and inline `traffic:` rates are
merged over the profiled out-port rates. `constraints:` holds the component's own Table I
thresholds (cpu_below, mem_free_above, battery_above), which narrow the fleet's
(`Thresholds.stricter`); a Table II key there is refused with where it belongs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from sdrpeer.errors import ProfileFileError, SpecError, shown
from sdrpeer.runtime.spec import _launcher, _name, _target
from sdrpeer.system.classes import ClassInfo, check_params, inspect_target
from sdrpeer.system.model import (
    RECONCILE,
    STANDBY_MODES,
    ComponentDef,
    DisconnectSpec,
    Requirements,
    StandbySpec,
    Thresholds,
)
from sdrpeer.system.paths import resolve_exec_target, resolve_script_target
from sdrpeer.system.problems import MISSING, Problems
from sdrpeer.system.profiles import ProfileFigures, read_profile
from sdrpeer.system.sections import ROBOT_KEYS, read_thresholds
from sdrpeer.system.values import (
    boolean,
    bounded,
    integer,
    param_value,
    parse_bandwidth,
    robot_name,
    robot_names,
    text,
)
from sdrpeer.units import parse_duration, parse_percent, parse_size

COMPONENT_KEYS = (
    "name",
    "launcher",
    "target",
    "params",
    "profile",
    "requires",
    "standby",
    "pin",
    "prefer",
    "watchdog",
    "disconnect",
    "constraints",
)
REQUIRES_KEYS = ("cpu", "memory", "traffic")
STANDBY_KEYS = ("same_robot", "other_robots", "mode", "sync")
DISCONNECT_KEYS = ("stop_after", "replace", "lost_after", "reconcile")

parse_cpu = bounded(parse_percent, 0.0, 10_000.0, "0% to 10000%: percent of one core")
parse_memory = bounded(lambda v: float(parse_size(v)), 0.0, 1e12, "0 to 1TB")


@dataclass
class ComponentEntry:
    """One component as read, with what the connections check needs."""

    node: yaml.Node
    where: str
    info: ClassInfo | None
    """The imported class (python launcher), None when its ports cannot be known."""
    definition: ComponentDef | None
    """None when something in the component was wrong."""


def read_components(p: Problems, node: yaml.Node, base_dir: Path) -> dict[str, ComponentEntry]:
    """Every component by name (duplicates and problems recorded in `p`)."""
    out: dict[str, ComponentEntry] = {}
    items = p.sequence(node, "components")
    if isinstance(node, yaml.SequenceNode) and not items:
        p.add(node, "components", "a system needs at least one component")
    for i, item in enumerate(items):
        where = f"components[{i}]"
        fields = p.mapping(item, where, COMPONENT_KEYS, ("name", "target"))
        if fields is None:
            continue
        name, entry = read_component(p, fields, item, where, base_dir)
        if not name:
            continue
        if name in out:
            first = out[name].node.start_mark.line + 1
            p.add(fields["name"], f"{where}.name", f"{name!r} given twice (first at line {first})")
            continue
        out[name] = entry
    return out


def read_component(
    p: Problems,
    fields: dict[str, yaml.Node],
    node: yaml.Node,
    where: str,
    base_dir: Path,
    *,
    files: bool = True,
) -> tuple[str, ComponentEntry]:
    """One component's fields (already checked for unknown keys) -> its name and entry.
    `files`: resolve and check the file a `script` or `exec` target names (a composite's member
    runs no file: its launcher is refused instead)."""
    errors_before = len(p.items)
    name = _spec_field(p, fields, "name", where, _name)
    launcher = _spec_field(p, fields, "launcher", where, _launcher, default="python")
    target: Any = MISSING
    if launcher and "target" in fields:
        target = _spec_field(p, fields, "target", where, lambda v, w: _target(launcher, v, w))
    if target and files:
        target = _resolve_paths(
            p, fields["target"], f"{where}.target", (launcher, target), base_dir
        )
    info: ClassInfo | None = None
    if target:
        with p.guard():
            info = p.f.parse(
                fields["target"], f"{where}.target", lambda _: inspect_target(launcher, target)
            )
    params = _params(p, fields, where, info)
    figures: ProfileFigures | None = None
    if "profile" in fields:
        figures = _profile(p, fields["profile"], f"{where}.profile", base_dir, target)
    requires = _requires(p, fields, where, figures, info)
    standby = _standby(p, fields, where)
    pin = p.get(fields, "pin", where, robot_name, None)
    prefer = p.get(fields, "prefer", where, robot_names, ())
    watchdog = p.get(fields, "watchdog", where, _watchdog, None)
    disconnect = _disconnect(p, fields, where)
    thresholds = Thresholds()
    if "constraints" in fields:
        thresholds = read_thresholds(p, fields["constraints"], f"{where}.constraints", ROBOT_KEYS)
    definition = None
    if len(p.items) == errors_before:
        definition = ComponentDef(
            name=name,
            launcher=launcher,
            target=target,
            params=params,
            requires=requires,
            standby=standby,
            pin=pin,
            prefer=prefer,
            watchdog_s=watchdog,
            disconnect=disconnect,
            thresholds=thresholds,
        )
    if not name and "name" in fields:  # a bad name still names it for the connections
        raw = p.f.value(fields["name"])
        name = raw if isinstance(raw, str) else MISSING
    return name, ComponentEntry(node, where, info, definition)


def _resolve_paths(
    p: Problems, node: yaml.Node, where: str, spec: tuple[str, Any], base_dir: Path
) -> Any:
    """A `script` or `exec` target with the file it names made absolute against the system
    file's directory (sdrpeer.system.paths); MISSING, with the problem recorded, when that file
    does not exist."""
    launcher, target = spec
    try:
        if launcher == "script" and isinstance(target, str):
            return resolve_script_target(base_dir, target)
        if launcher == "exec" and isinstance(target, tuple):
            return resolve_exec_target(base_dir, target)
    except ValueError as e:
        p.add(node, where, str(e))
        return MISSING
    return target


def _watchdog(value: object) -> float:
    """0 (off), or 0.5s to 600s: how long a host may go without a heartbeat."""
    seconds = parse_duration(value)
    if seconds != 0 and not 0.5 <= seconds <= 600:
        raise ValueError(f"{value!r} is out of range (0 for none, or 0.5s to 600s)")
    return seconds


def _spec_field(
    p: Problems,
    fields: dict[str, yaml.Node],
    key: str,
    where: str,
    check: Callable[[Any, str], Any],
    *,
    default: Any = None,
) -> Any:
    """A field checked by one of the instance spec's validators."""
    node = fields.get(key)
    if node is None:
        return default if default is not None else MISSING
    try:
        return check(p.f.value(node), f"{where}.{key}")
    except SpecError as e:
        p.add(node, e.field, str(e).split("': ", 1)[-1])
        return MISSING


def _params(
    p: Problems, fields: dict[str, yaml.Node], where: str, info: ClassInfo | None
) -> tuple[tuple[str, Any], ...]:
    node = fields.get("params")
    if node is None:
        return ()
    items = p.mapping(node, f"{where}.params", None)
    if items is None:
        return ()
    values: dict[str, Any] = {}
    for key, value_node in items.items():
        value = p.get(items, key, f"{where}.params", param_value, MISSING)
        if value is MISSING:
            continue
        values[key] = value
        if info is not None:
            for _, message in check_params(info, {key: value}):
                p.add(value_node, f"{where}.params.{key}", message)
    return tuple(sorted(values.items()))


def _profile(
    p: Problems, node: yaml.Node, where: str, base_dir: Path, target: Any
) -> ProfileFigures | None:
    path: str = MISSING
    with p.guard():
        path = p.f.parse(node, where, text)
    if not path:
        return None
    try:
        figures = read_profile(base_dir / path, path)
    except ProfileFileError as e:
        p.add(node, where, str(e))
        return None
    if isinstance(target, str) and figures.target is not None and figures.target != target:
        p.add(node, where, f"{path} was measured for {figures.target}, not {target}")
        return None
    return figures


def _requires(
    p: Problems,
    fields: dict[str, yaml.Node],
    where: str,
    figures: ProfileFigures | None,
    info: ClassInfo | None,
) -> Requirements:
    cpu = figures.cpu_pct if figures else 0.0
    mem = figures.mem_bytes if figures else 0
    rates = dict(figures.out_bytes_per_s) if figures else {}
    node = fields.get("requires")
    inline = p.mapping(node, f"{where}.requires", REQUIRES_KEYS) if node is not None else {}
    if inline:
        cpu = p.get(inline, "cpu", f"{where}.requires", parse_cpu, cpu)
        mem = round(p.get(inline, "memory", f"{where}.requires", parse_memory, float(mem)) or 0)
        rates.update(_traffic(p, inline.get("traffic"), f"{where}.requires.traffic", info))
    return Requirements(
        cpu_pct=cpu or 0.0,
        mem_bytes=mem,
        out_bytes_per_s=tuple(sorted(rates.items())),
        profile=figures.path if figures else None,
    )


def _traffic(
    p: Problems, node: yaml.Node | None, where: str, info: ClassInfo | None
) -> dict[str, float]:
    if node is None:
        return {}
    items = p.mapping(node, where, None)
    out: dict[str, float] = {}
    for port, value_node in (items or {}).items():
        rate = p.get(items or {}, port, where, parse_bandwidth, MISSING)
        if info is not None and port not in info.out_ports:
            p.add(
                value_node,
                f"{where}.{port}",
                f"no OutPort {port!r} (out ports: {info.ports_text('out')})",
            )
        elif rate is not MISSING:
            out[port] = rate
    return out


def _block(
    p: Problems, fields: dict[str, yaml.Node], key: str, where: str, keys: tuple[str, ...]
) -> tuple[dict[str, yaml.Node], str] | None:
    """The mapping under `key` with its dotted name; None when absent or not a mapping."""
    node = fields.get(key)
    items = None if node is None else p.mapping(node, f"{where}.{key}", keys)
    return None if items is None else (items, f"{where}.{key}")


def _standby(p: Problems, fields: dict[str, yaml.Node], where: str) -> StandbySpec:
    block = _block(p, fields, "standby", where, STANDBY_KEYS)
    if block is None:
        return StandbySpec()
    items, w = block
    return StandbySpec(
        same_robot=p.get(items, "same_robot", w, integer(0, 16), 0),
        other_robots=p.get(items, "other_robots", w, integer(0, 64), 0),
        mode=p.get(items, "mode", w, _mode, "hot"),
        sync_s=p.get(items, "sync", w, bounded(parse_duration, 0, 3600, "0s to 3600s"), 0.0),
    )


def _disconnect(p: Problems, fields: dict[str, yaml.Node], where: str) -> DisconnectSpec:
    """`disconnect:` (sdrpeer.deploy.disconnect); without `stop_after`, a component the fleet
    does not replace keeps running on a robot cut off (one copy either way)."""
    block = _block(p, fields, "disconnect", where, DISCONNECT_KEYS)
    if block is None:
        return DisconnectSpec()
    items, w = block
    replace = p.get(items, "replace", w, boolean, True)
    return DisconnectSpec(
        stop_after_s=p.get(items, "stop_after", w, _stop_after, 0.0 if replace else None),
        replace=replace,
        lost_after_s=p.get(items, "lost_after", w, _lost_after, 0.0),
        reconcile=p.get(items, "reconcile", w, _reconcile, "keep_replacement"),
    )


_lost_after = bounded(parse_duration, 0, 86_400, "0s to 86400s")


def _stop_after(value: object) -> float | None:
    """`never`, or 0s to 86400s."""
    if value == "never":
        return None
    try:
        return _lost_after(value)
    except ValueError as e:
        raise ValueError(f"{e} (or never)") from None


def _reconcile(value: object) -> str:
    if value not in RECONCILE:
        raise ValueError(f"expected one of {', '.join(RECONCILE)}, got {shown(value)}")
    return str(value)


def _mode(value: object) -> str:
    if value not in STANDBY_MODES:
        raise ValueError(f"expected one of {', '.join(STANDBY_MODES)}, got {shown(value)}")
    return str(value)
