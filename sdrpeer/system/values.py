"""Small value parsers of the system file: bounded quantities, counts, names, data rates.

How it works: each is a plain function `value -> parsed` raising ValueError with a message for
people, so `YamlFile.parse` (through `Problems.get`) can report it at the value's line.
`bounded(parser, low, high, shown)` wraps a sdrpeer.units parser with a range check.
`parse_bandwidth` reads traffic: `200kB/s`, `1.5MB/s`, or a plain number of bytes per second.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from sdrpeer.config import MAX_NAME, NAME_RE
from sdrpeer.errors import shown
from sdrpeer.units import parse_size

MAX_RATE = 100e9
"""Traffic above 100 GB/s is a typo, not a plan."""


def bounded(
    parser: Callable[[object], float], low: float, high: float, shown: str
) -> Callable[[object], float]:
    """`parser` that also refuses values outside [low, high] (`shown` is the range as written)."""

    def parse(value: object) -> float:
        out = parser(value)
        if not low <= out <= high:
            raise ValueError(f"{value!r} is out of range ({shown})")
        return out

    return parse


def parse_bandwidth(value: object) -> float:
    """`200kB/s`, `1.5MB/s`, `512KiB/s`, `190000` -> bytes per second (up to 100 GB/s)."""
    text = value
    if isinstance(value, str):
        text = value.strip()
        if not text.lower().endswith("/s"):
            raise ValueError(f"expected a data rate such as 200kB/s, got {shown(value)}")
        text = text[:-2]
    try:
        out = parse_size_float(text)
    except ValueError:
        raise ValueError(f"expected a data rate such as 200kB/s, got {shown(value)}") from None
    if out > MAX_RATE:
        raise ValueError(f"{value!r} is out of range (0 to 100GB/s)")
    return out


def parse_size_float(value: object) -> float:
    """Like `parse_size` but keeps fractions of a byte (rates need not be whole)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"expected a size such as 500MB, got {shown(value)}")
        return float(value)
    return float(parse_size(value))


def integer(low: int, high: int) -> Callable[[object], int]:
    """A parser of whole numbers in [low, high]."""

    def parse(value: object) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"expected a whole number, got {shown(value)}")
        if not low <= value <= high:
            raise ValueError(f"{value!r} is out of range ({low} to {high})")
        return value

    return parse


def robot_name(value: object) -> str:
    """A robot's name ([A-Za-z0-9_.-]+); robots are not known at load time, only the form is."""
    if not isinstance(value, str) or not NAME_RE.fullmatch(value):
        raise ValueError(f"expected a robot name of [A-Za-z0-9_.-], got {shown(value)}")
    if len(value) > MAX_NAME:
        raise ValueError(f"a robot name has at most {MAX_NAME} characters, got {shown(value)}")
    return value


def robot_names(value: object) -> tuple[str, ...]:
    """A list of distinct robot names."""
    if not isinstance(value, list):
        raise ValueError(f"expected a list of robot names, got {shown(value)}")
    names = tuple(robot_name(v) for v in value)
    for i, name in enumerate(names):
        if name in names[:i]:
            raise ValueError(f"{name!r} is listed twice")
    return names


def boolean(value: object) -> bool:
    """true or false (YAML booleans only: 'yes' in quotes is a string)."""
    if not isinstance(value, bool):
        raise ValueError(f"expected true or false, got {shown(value)}")
    return value


def text(value: object) -> str:
    """A non-empty string."""
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"expected a non-empty string, got {shown(value)}")
    return value


def param_value(value: Any) -> Any:
    """A parameter value: a string, number or boolean, or a list of those (kept as a tuple)."""
    if isinstance(value, list):
        return tuple(param_value(v) for v in value)
    if not isinstance(value, str | int | float | bool):
        raise ValueError(
            f"expected a string, number, boolean or a list of them, got {shown(value)}"
        )
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {shown(value)}")
    return value
