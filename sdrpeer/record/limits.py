"""The ranges of every robot fact that can reach a gossip record: one table for all inputs.

How it works: robot files, scenarios and the live API (`POST /v1/robot`, `sdrpeer robot set`)
parse a value with `sdrpeer.units`, then `check(name, value)` refuses anything outside its
`LIMITS` entry with a message in the project's words ("rssi: -1000dBm is out of range (-150dBm to
0dBm)"). The record codec (`sdrpeer.record.robot`) clamps to the same table when it encodes, so a
record can never fail to encode whatever a measurement says, and its decoder's ranges contain
these. Values are in base units: percent, dBm, metres, bytes, percent per second, seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sdrpeer.errors import shown


@dataclass(frozen=True, slots=True)
class Limit:
    """An inclusive range and how to show it."""

    low: float
    high: float
    shown: str

    def clamp(self, value: float) -> float:
        """`value` brought inside the range (NaN becomes the low end)."""
        if math.isnan(value):
            return self.low
        return min(self.high, max(self.low, value))


MAX_COORD_M = 10_000_000.0
"""Largest position coordinate, either sign (10,000 km: the wire carries centimetres)."""

LIMITS: dict[str, Limit] = {
    "battery": Limit(0.0, 100.0, "0% to 100%"),
    "rssi": Limit(-150.0, 0.0, "-150dBm to 0dBm"),
    "rssi_noise": Limit(0.0, 30.0, "0dB to 30dB"),
    "coord": Limit(-MAX_COORD_M, MAX_COORD_M, "-10000km to 10000km"),
    "memory": Limit(1_000_000.0, float(2**50), "1MB to 1PiB"),
    "cpus": Limit(1, 4096, "1 to 4096"),
    "drain": Limit(-100 / 60, 100 / 60, "-100%/min to 100%/min (negative: charging)"),
    "priority": Limit(-(2**31), 2**31 - 1, "-2147483648 to 2147483647"),
    "clock_skew": Limit(-86_400.0, 86_400.0, "-1d to 1d"),
    "cpu_pct": Limit(0.0, 10_000.0, "0% to 10000%"),
}
"""Every bounded robot fact, by the name its inputs use."""


def check_int(name: str, value: object, example: str = "0") -> int:
    """`value` if it is an integer inside `LIMITS[name]` (compared exactly, however big), else
    ValueError naming the range."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"expected an integer such as {example}, got {shown(value)}")
    limit = LIMITS[name]
    if not limit.low <= value <= limit.high:
        raise ValueError(f"{value!r} is out of range ({limit.shown})")
    return value


def check(name: str, value: float, written: object = None) -> float:
    """`value` if inside `LIMITS[name]`, else ValueError naming the range (`written`: the value
    as the user wrote it, for the message)."""
    limit = LIMITS[name]
    if not (math.isfinite(value) and limit.low <= value <= limit.high):
        shown = value if written is None else written
        raise ValueError(f"{shown!r} is out of range ({limit.shown})")
    return value
