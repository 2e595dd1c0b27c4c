"""The quantities of a system file: metrics in conditions, thresholds, traffic, with their bounds.

How it works: `METRICS` maps each metric a recovery rule may watch (mem_free, cpu, battery, rssi,
delay, jitter, loss) to a `Metric`: the sdrpeer.units parser for what people write, the factor to
the model's base unit (delay and jitter are kept in ms, loss as a fraction) and the sane range.
`parse_condition("rssi <= -52.5dBm")` splits a `when:` into (metric, op, value in base units).
Each metric's range is checked, so "-5%" or "900%" are refused with an example in the message.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

from sdrpeer.units import parse_duration, parse_percent, parse_power, parse_size

OPS = ("<=", "<", ">=", ">")
_CONDITION = re.compile(r"^\s*([a-z_]+)\s*(<=|>=|<|>)\s*(\S.*?)\s*$")


@dataclass(frozen=True, slots=True)
class Metric:
    """How one metric is written and stored."""

    parser: Callable[[object], float]
    """Reads what people write (a sdrpeer.units parser)."""
    factor: float
    """Multiplies the parsed value into the model's base unit."""
    low: float
    high: float
    """The sane range, in the parser's unit."""
    example: str
    """A value as people write it (for messages)."""
    falls: bool
    """True if the metric is bad when low (mem_free, battery, rssi): a rule uses < or <=."""

    def parse(self, value: object) -> float:
        """The value in base units; ValueError if unreadable or out of range."""
        out = self.parser(value)
        if not self.low <= out <= self.high:
            raise ValueError(f"{value!r} is out of range (expected something like {self.example})")
        return out * self.factor


METRICS: dict[str, Metric] = {
    "mem_free": Metric(lambda v: float(parse_size(v)), 1.0, 0, 1e15, "200MB", falls=True),
    "cpu": Metric(parse_percent, 1.0, 0, 100, "90%", falls=False),
    "battery": Metric(parse_percent, 1.0, 0, 100, "15%", falls=True),
    "rssi": Metric(parse_power, 1.0, -150, 0, "-52.5dBm", falls=True),
    "delay": Metric(parse_duration, 1000.0, 0, 600, "200ms", falls=False),
    "jitter": Metric(parse_duration, 1000.0, 0, 600, "50ms", falls=False),
    "loss": Metric(parse_percent, 0.01, 0, 100, "30%", falls=False),
}
"""Metric name -> how it is read; base units: bytes, %, dBm, ms, ms, fraction 0..1."""


def parse_condition(text: object) -> tuple[str, str, float]:
    """`"rssi <= -52.5dBm"` -> ("rssi", "<=", -52.5); ValueError naming what is wrong."""
    if not isinstance(text, str):
        raise ValueError(f"expected a condition such as 'mem_free <= 200MB', got {text!r}")
    match = _CONDITION.match(text)
    if match is None:
        raise ValueError(f"expected 'METRIC OP VALUE' such as 'rssi <= -52.5dBm', got {text!r}")
    metric, op, value = match.groups()
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r} (known: {', '.join(METRICS)})")
    return metric, op, METRICS[metric].parse(value)
