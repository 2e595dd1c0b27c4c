"""Passive monitoring: traps are threshold crossings, broadcast at once instead of polled.

How it works: a `TrapRule` watches one metric with hysteresis. A rule `rssi_dbm <= -52.5, clear
-50` is *raised* when a sample is at or below -52.5 and, once raised, *cleared* only when a
sample is no longer at or below -50 (i.e. above -50). Between the two levels nothing fires, so
a value wobbling around the threshold makes one trap, not one per sample. `TrapDetector.feed`
returns only the new crossings; a metric the robot does not have (None) changes nothing. Traps
travel in gossip `Event(kind="trap")` payloads, encoded by `encode_trap` and checked by
`decode_trap` (which raises only `RecordError("malformed", ...)`).

Default rules follow the paper's Table VI where it gives values ("or less" is `<=`): free
memory <= 200MB (clears above 250MB), RSSI <= -52.5 dBm (clears above -50 dBm); plus battery
< 20 % (clears at 25 %) and cpu > 90 % (clears at 80 %).

Who hears a trap: a rule with `broadcast` (battery, RSSI) sends its traps to every robot, since
other robots act on them (robot-wide recovery, who may be allocator); the others (memory, CPU)
are acted on by the robot's own agent (Table III's local recovery) and stay in its event log,
while the fleet sees the values in its vitals. Broadcasting every robot's CPU trap would cost
every robot a share that grows with the fleet.
"""

from __future__ import annotations

import math
import operator
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import msgpack

from sdrpeer.errors import RecordError
from sdrpeer.record.robot import Metrics

METRICS = ("cpu_pct", "mem_free", "battery_pct", "rssi_dbm")
"""Metrics a rule may watch (fields of `Metrics`)."""
_OPS: dict[str, Callable[[float, float], bool]] = {
    "<": operator.lt,
    "<=": operator.le,
    ">": operator.gt,
    ">=": operator.ge,
}
_STATES = ("raised", "cleared")
_FORMAT = 1
_METRIC_RE = re.compile(r"[a-z][a-z0-9_]{0,31}")


@dataclass(frozen=True, slots=True)
class TrapRule:
    """Raise when `metric op threshold` holds; clear when `metric op clear` no longer holds."""

    metric: str
    op: str
    threshold: float
    clear: float
    broadcast: bool = True
    """Whether its traps go to every robot (else only into this robot's event log)."""

    def __post_init__(self) -> None:
        if self.metric not in METRICS:
            raise ValueError(f"unknown metric {self.metric!r} (known: {', '.join(METRICS)})")
        if self.op not in _OPS:
            raise ValueError(f"op must be one of {', '.join(_OPS)}, got {self.op!r}")
        low = self.op.startswith("<")
        if (low and self.clear < self.threshold) or (not low and self.clear > self.threshold):
            side = "at or above" if low else "at or below"
            raise ValueError(f"{self.metric}: clear level must be {side} the threshold")

    def holds(self, value: float, level: float) -> bool:
        """Whether `value op level`."""
        return _OPS[self.op](value, level)


@dataclass(frozen=True, slots=True)
class Trap:
    """A crossing: `metric` reached `value` at `ts`; `threshold` identifies the rule."""

    metric: str
    value: float
    threshold: float
    state: str
    """"raised" or "cleared"."""
    ts: float
    broadcast: bool = True
    """Whether the rule sends it to every robot (not on the wire)."""


def default_rules() -> tuple[TrapRule, ...]:
    """A robot's default traps (paper Table VI values for memory and RSSI)."""
    return (
        TrapRule("mem_free", "<=", 200_000_000, 250_000_000, broadcast=False),
        TrapRule("battery_pct", "<", 20.0, 25.0),
        TrapRule("rssi_dbm", "<=", -52.5, -50.0),
        TrapRule("cpu_pct", ">", 90.0, 80.0, broadcast=False),
    )


class TrapDetector:
    """Turns a stream of metric samples into trap crossings, once per crossing."""

    def __init__(self, rules: Iterable[TrapRule] | None = None) -> None:
        self.rules = tuple(default_rules() if rules is None else rules)
        self._raised = [False] * len(self.rules)

    def feed(self, metrics: Metrics, now: float) -> list[Trap]:
        """New crossings caused by this sample (usually none)."""
        traps = []
        for i, rule in enumerate(self.rules):
            value = getattr(metrics, rule.metric)
            if value is None:
                continue
            if not self._raised[i] and rule.holds(value, rule.threshold):
                self._raised[i] = True
                traps.append(
                    Trap(rule.metric, float(value), rule.threshold, "raised", now, rule.broadcast)
                )
            elif self._raised[i] and not rule.holds(value, rule.clear):
                self._raised[i] = False
                traps.append(
                    Trap(rule.metric, float(value), rule.threshold, "cleared", now, rule.broadcast)
                )
        return traps

    def raised(self) -> list[TrapRule]:
        """Rules currently raised."""
        return [r for r, up in zip(self.rules, self._raised, strict=True) if up]


def encode_trap(t: Trap) -> bytes:
    """A trap as msgpack bytes: [format, metric, value, threshold, state, ts]."""
    wire = [_FORMAT, t.metric, float(t.value), float(t.threshold), _STATES.index(t.state), t.ts]
    data: bytes = msgpack.packb(wire, use_bin_type=True)
    return data


def _finite(x: object, what: str) -> float:
    """A finite float from the wire (ints accepted)."""
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        raise RecordError("malformed", f"trap: {what}: expected a finite number")
    return float(x)


def decode_trap(b: bytes) -> Trap:
    """Bytes from an Event(kind="trap") -> a checked Trap; raises RecordError("malformed")."""
    try:
        wire = msgpack.unpackb(b, raw=False, strict_map_key=True, use_list=True)
    except Exception as e:  # msgpack raises many types on garbage; all mean the same here
        raise RecordError("malformed", f"trap: not msgpack ({type(e).__name__})") from None
    if not isinstance(wire, list) or len(wire) != 6:
        raise RecordError("malformed", "trap: expected a list of 6")
    fmt, metric, value, threshold, state, ts = wire
    if fmt != _FORMAT or isinstance(fmt, bool):
        raise RecordError("malformed", f"trap: format {fmt!r} not understood")
    if not isinstance(metric, str) or not _METRIC_RE.fullmatch(metric):
        raise RecordError("malformed", "trap: metric: expected a metric name")
    if isinstance(state, bool) or not isinstance(state, int) or state not in (0, 1):
        raise RecordError("malformed", "trap: state: expected 0 or 1")
    return Trap(
        metric=metric,
        value=_finite(value, "value"),
        threshold=_finite(threshold, "threshold"),
        state=_STATES[state],
        ts=_finite(ts, "ts"),
    )
