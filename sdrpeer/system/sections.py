"""The `allocation:` and `recovery:` sections (Tables I, II and III of the paper).

How it works: thresholds are written in the paper's words (`cpu_below: 80%`,
`mem_free_above: 500MB`, `rssi_above: -60dBm` ...) and stored in base units (`Thresholds`).
Strategy and constraint plugin names are checked against the installed entry point groups
`sdrpeer.strategies` and `sdrpeer.constraints` (names only: nothing is imported). A recovery rule
names a cause (sdrpeer.system.recovery_defaults.CAUSES), a `when:` condition on one of the
metrics that cause watches (events have none), how long it must hold (`for:`), where it clears
(`clear:`, on the healthy side of the threshold) and its ladder of actions. Without a `recovery:`
section, or without `rules:` in it, the rules are Table III's (`default_recovery()`).
"""

from __future__ import annotations

from collections.abc import Callable
from importlib.metadata import entry_points
from typing import Any

import yaml

from sdrpeer.errors import shown
from sdrpeer.system.metrics import METRICS, parse_condition
from sdrpeer.system.model import (
    ON_VIOLATION,
    QUORUMS,
    AllocationDef,
    ComplianceDef,
    RecoveryDef,
    RecoveryRule,
    StreamsDef,
    Thresholds,
)
from sdrpeer.system.problems import MISSING, Problems
from sdrpeer.system.recovery_defaults import ACTIONS, CAUSES, default_recovery
from sdrpeer.system.values import boolean, bounded, integer
from sdrpeer.units import (
    parse_distance,
    parse_duration,
    parse_percent,
    parse_power,
    parse_size,
)

ALLOCATION_KEYS = ("strategy", "constraints", "weights", "plugins", "preempt", "quorum")
RECOVERY_KEYS = ("rules", "max_attempts", "window", "min_dwell")
RULE_KEYS = ("cause", "when", "for", "clear", "actions")
BUILTIN_STRATEGIES = ("first_fit", "objective")
WEIGHT_TERMS = ("mem_free", "battery", "rssi", "distance", "traffic_local", "load")
STRATEGY_GROUP = "sdrpeer.strategies"
CONSTRAINT_GROUP = "sdrpeer.constraints"


def _limit(
    parser: Callable[[object], float],
    low: float,
    high: float,
    shown: str,
    *,
    above_low: bool = False,
    factor: float = 1.0,
) -> Callable[[object], float]:
    """A threshold read by `parser`, checked against [low, high] (or (low, high]), times factor."""

    def parse(value: object) -> float:
        out = parser(value)
        if out < low or out > high or (above_low and out == low):
            raise ValueError(f"{value!r} is out of range ({shown})")
        return out * factor

    return parse


def _size(value: object) -> int:
    return parse_size(value)


THRESHOLDS: dict[str, tuple[str, Callable[[object], Any]]] = {
    "cpu_below": (
        "cpu_below_pct",
        _limit(parse_percent, 0, 100, "above 0% up to 100%", above_low=True),
    ),
    "mem_free_above": (
        "mem_free_above_bytes",
        lambda v: round(_limit(_size, 0, 1e12, "0 to 1TB")(v)),
    ),
    "battery_above": ("battery_above_pct", _limit(parse_percent, 0, 100, "0% to 100%")),
    "rssi_above": ("rssi_above_dbm", _limit(parse_power, -150, 0, "-150dBm to 0dBm")),
    "jitter_below": (
        "jitter_below_ms",
        _limit(parse_duration, 0, 60, "above 0 up to 60s", above_low=True, factor=1000),
    ),
    "distance_below": (
        "distance_below_m",
        _limit(parse_distance, 0, 1e6, "above 0 up to 1000km", above_low=True),
    ),
    "loss_below": (
        "loss_below",
        _limit(parse_percent, 0, 100, "above 0% up to 100%", above_low=True, factor=0.01),
    ),
    "delay_below": (
        "delay_below_ms",
        _limit(parse_duration, 0, 60, "above 0 up to 60s", above_low=True, factor=1000),
    ),
}
"""File key -> (Thresholds field, parser to base units)."""


def installed(group: str) -> list[str]:
    """The names in an entry point group."""
    return sorted({ep.name for ep in entry_points(group=group)})


def read_streams(p: Problems, node: yaml.Node | None) -> StreamsDef:
    """The streams section (defaults when absent): `encrypt` for every port stream."""
    if node is None:
        return StreamsDef()
    fields = p.mapping(node, "streams", ("encrypt",))
    if fields is None:
        return StreamsDef()
    return StreamsDef(encrypt=p.get(fields, "encrypt", "streams", boolean, True))


def read_allocation(p: Problems, node: yaml.Node | None) -> AllocationDef:
    """The allocation section (defaults when absent)."""
    if node is None:
        return AllocationDef()
    fields = p.mapping(node, "allocation", ALLOCATION_KEYS)
    if fields is None:
        return AllocationDef()
    strategy = p.get(fields, "strategy", "allocation", _one_of(installed(STRATEGY_GROUP)), "")
    thresholds = Thresholds()
    if "constraints" in fields:
        thresholds = _thresholds(p, fields["constraints"])
    builtin = strategy in BUILTIN_STRATEGIES or strategy == ""
    weights = p.get(fields, "weights", "allocation", _weights(builtin), ())
    plugins = p.get(fields, "plugins", "allocation", _names(installed(CONSTRAINT_GROUP)), ())
    return AllocationDef(
        strategy=strategy or "first_fit",
        thresholds=thresholds,
        weights=weights,
        constraints=plugins,
        preempt=p.get(fields, "preempt", "allocation", boolean, False),
        quorum=p.get(fields, "quorum", "allocation", _one_of(list(QUORUMS)), "majority"),
    )


def _thresholds(p: Problems, node: yaml.Node) -> Thresholds:
    return read_thresholds(p, node, "allocation.constraints", tuple(THRESHOLDS))


ROBOT_KEYS = ("cpu_below", "mem_free_above", "battery_above")
"""Table I: the thresholds a component's own `constraints:` may set."""
LINK_KEYS = ("rssi_above", "jitter_below", "distance_below", "loss_below", "delay_below")
"""Table II: the bounds a connection's own `constraints:` may set."""


def read_thresholds(p: Problems, node: yaml.Node, where: str, keys: tuple[str, ...]) -> Thresholds:
    """A `constraints:` mapping of `keys` (THRESHOLDS' file keys) into `Thresholds`; a key of the
    other table is reported with where it belongs."""
    fields = p.mapping(node, where, None)
    values: dict[str, Any] = {}
    for key, value_node in (fields or {}).items():
        if key not in THRESHOLDS:
            p.add(value_node, f"{where}.{key}", f"unknown field (known: {', '.join(keys)})")
            continue
        if key not in keys:
            belongs = "a connection's" if key in LINK_KEYS else "a component's"
            p.add(
                value_node,
                f"{where}.{key}",
                f"{key} is not allowed here: it goes under {belongs} constraints "
                f"(here: {', '.join(keys)})",
            )
            continue
        attr, parser = THRESHOLDS[key]
        with p.guard():
            values[attr] = p.f.parse(value_node, f"{where}.{key}", parser)
    return Thresholds(**values)


COMPLIANCE_KEYS = ("on_violation", "for", "clear", "min_interval")


def read_compliance(p: Problems, node: yaml.Node | None) -> ComplianceDef:
    """The compliance section (defaults when absent): what a violated placement leads to."""
    if node is None:
        return ComplianceDef()
    fields = p.mapping(node, "compliance", COMPLIANCE_KEYS)
    if fields is None:
        return ComplianceDef()
    return ComplianceDef(
        on_violation=p.get(
            fields, "on_violation", "compliance", _one_of(list(ON_VIOLATION)), "report"
        ),
        sustain_s=p.get(fields, "for", "compliance", _duration(0, 3600), 5.0),
        clear=p.get(
            fields,
            "clear",
            "compliance",
            _limit(parse_percent, 0, 20, "0% to 20%", factor=0.01),
            0.1,
        ),
        min_interval_s=p.get(fields, "min_interval", "compliance", _duration(0, 86400), 60.0),
    )


def _one_of(names: list[str]) -> Callable[[object], str]:
    def parse(value: object) -> str:
        if value not in names:
            raise ValueError(f"expected one of {', '.join(names)}, got {shown(value)}")
        return str(value)

    return parse


def _names(known: list[str]) -> Callable[[object], tuple[str, ...]]:
    one = _one_of(known)

    def parse(value: object) -> tuple[str, ...]:
        if not isinstance(value, list):
            raise ValueError(f"expected a list of plugin names, got {shown(value)}")
        names = tuple(one(v) for v in value)
        for i, name in enumerate(names):
            if name in names[:i]:
                raise ValueError(f"{name!r} is listed twice")
        return names

    return parse


def _weights(builtin: bool) -> Callable[[object], tuple[tuple[str, float], ...]]:
    def parse(value: object) -> tuple[tuple[str, float], ...]:
        if not isinstance(value, dict):
            raise ValueError(f"expected a mapping of term -> weight, got {shown(value)}")
        out = []
        for term, weight in value.items():
            if builtin and term not in WEIGHT_TERMS:
                raise ValueError(f"unknown term {term!r} (known: {', '.join(WEIGHT_TERMS)})")
            if not isinstance(term, str) or not term.isidentifier():
                raise ValueError(f"a term is an identifier, got {term!r}")
            if isinstance(weight, bool) or not isinstance(weight, int | float):
                raise ValueError(f"weight of {term!r}: expected a number, got {weight!r}")
            if not 0 <= weight <= 1e6:
                raise ValueError(f"weight of {term!r}: expected 0 to 1e6, got {weight!r}")
            out.append((term, float(weight)))
        return tuple(sorted(out))

    return parse


def read_recovery(p: Problems, node: yaml.Node | None) -> RecoveryDef:
    """The recovery section (Table III defaults when absent)."""
    defaults = default_recovery()
    if node is None:
        return defaults
    fields = p.mapping(node, "recovery", RECOVERY_KEYS)
    if fields is None:
        return defaults
    rules = defaults.rules
    if "rules" in fields:
        rules = _rules(p, fields["rules"])
    return RecoveryDef(
        rules=rules,
        max_attempts=p.get(fields, "max_attempts", "recovery", integer(1, 100), 3),
        window_s=p.get(fields, "window", "recovery", _duration(0.001, 86400), 60.0),
        min_dwell_s=p.get(fields, "min_dwell", "recovery", _duration(0, 86400), 30.0),
    )


def _duration(low: float, high: float) -> Callable[[object], float]:
    return bounded(parse_duration, low, high, f"{low:g}s to {high:g}s")


def _rules(p: Problems, node: yaml.Node) -> tuple[RecoveryRule, ...]:
    out: list[RecoveryRule] = []
    seen: dict[tuple[str, str | None], int] = {}
    for i, item in enumerate(p.sequence(node, "recovery.rules")):
        where = f"recovery.rules[{i}]"
        fields = p.mapping(item, where, RULE_KEYS, ("cause", "actions"))
        if fields is None:
            continue
        before = len(p.items)
        rule = _rule(p, fields, item, where)
        if len(p.items) != before or rule is None:
            continue
        key = (rule.cause, rule.metric)
        if key in seen:
            what = rule.cause if rule.metric is None else f"{rule.cause} on {rule.metric}"
            p.add(item, where, f"a second rule for {what} (first at line {seen[key]})")
            continue
        seen[key] = item.start_mark.line + 1
        out.append(rule)
    return tuple(out)


def _rule(
    p: Problems, fields: dict[str, yaml.Node], item: yaml.Node, where: str
) -> RecoveryRule | None:
    cause = p.get(fields, "cause", where, _one_of(list(CAUSES)), MISSING)
    actions = p.get(fields, "actions", where, _actions, ())
    sustain = p.get(fields, "for", where, _duration(0, 3600), 0.0)
    if not cause:
        return None
    watched = CAUSES[cause]
    if not watched:
        for key in ("when", "for", "clear"):
            if key in fields:
                p.add(fields[key], f"{where}.{key}", f"{cause} is an event: it takes no {key}")
        return RecoveryRule(cause, actions=actions)
    if "when" not in fields:
        p.add(item, f"{where}.when", f"missing (required for {cause}: {' / '.join(watched)})")
        return None
    cond = p.get(fields, "when", where, parse_condition, MISSING)
    if cond is MISSING:
        return None
    metric, op, threshold = cond
    if metric not in watched:
        p.add(
            fields["when"], f"{where}.when", f"{cause} watches {', '.join(watched)}, not {metric}"
        )
        return None
    falls = METRICS[metric].falls
    if falls != op.startswith("<"):
        good = "< or <=" if falls else "> or >="
        p.add(
            fields["when"],
            f"{where}.when",
            f"{metric} is bad when {'low' if falls else 'high'}: use {good}",
        )
        return None
    clear = p.get(fields, "clear", where, METRICS[metric].parse, None)
    if (
        clear is not None
        and clear is not MISSING
        and (clear < threshold if falls else clear > threshold)
    ):
        side = "at or above" if falls else "at or below"
        p.add(fields["clear"], f"{where}.clear", f"must be {side} the threshold of `when`")
    return RecoveryRule(cause, metric, op, threshold, sustain, clear, actions)


def _actions(value: object) -> tuple[str, ...]:
    if not isinstance(value, list) or not value:
        raise ValueError(f"expected a non-empty list of actions ({', '.join(ACTIONS)})")
    one = _one_of(list(ACTIONS))
    names = tuple(one(v) for v in value)
    for i, name in enumerate(names):
        if name in names[:i]:
            raise ValueError(f"{name!r} is listed twice")
    return names
