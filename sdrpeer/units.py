"""Quantities as people write them in robot files, scenarios and system files.

How it works: a value is either a plain number (the kind's base unit is implied) or a string
`<number><unit>` (spaces allowed between the two). Each kind has one table of units -> factor
to its base unit; parsing looks the unit up and multiplies. Anything else raises `ValueError`
with a message naming the kind and an example, e.g. `expected a size such as 500MB, got '5XB'`.

Conventions (stated once, used everywhere):
- sizes -> int bytes. KB/MB/GB/TB and K/M/G/T are powers of 1000 (as disk and RAM vendors and
  Kubernetes write them); KiB/MiB/GiB/TiB and Ki/Mi/Gi/Ti are powers of 1024. Units are
  case-insensitive everywhere (`500mb` == `500MB`). A plain number is bytes.
- percents -> float percent (`80%` -> 80.0); plain numbers are percent.
- power -> float dBm (`-52.5dBm`); decibels (relative, e.g. noise) -> float dB (`1dB`).
- durations -> float seconds: us, µs, ms, s, sec, min, h. (`m` is not accepted: minutes or
  metres?) A plain number is seconds.
- distances -> float metres: mm, cm, m, km. Speeds -> metres per second: m/s, km/h, cm/s.
- rates -> percent per second: `%/s`, `%/min`, `%/h`. A plain number is %/s.
Sizes, durations, distances and speeds must not be negative; NaN and infinities are refused.
"""

from __future__ import annotations

import math
import re

from sdrpeer.errors import shown

_NUMBER = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_QUANTITY = re.compile(rf"^\s*({_NUMBER})\s*(\S*)\s*$")

_SIZE = {
    "": 1,
    "b": 1,
    "k": 1000,
    "kb": 1000,
    "m": 1000**2,
    "mb": 1000**2,
    "g": 1000**3,
    "gb": 1000**3,
    "t": 1000**4,
    "tb": 1000**4,
    "ki": 1024,
    "kib": 1024,
    "mi": 1024**2,
    "mib": 1024**2,
    "gi": 1024**3,
    "gib": 1024**3,
    "ti": 1024**4,
    "tib": 1024**4,
}
_PERCENT = {"": 1.0, "%": 1.0}
_POWER = {"": 1.0, "dbm": 1.0}
_DB = {"": 1.0, "db": 1.0}
_DURATION = {
    "": 1.0,
    "us": 1e-6,
    "µs": 1e-6,
    "ms": 1e-3,
    "s": 1.0,
    "sec": 1.0,
    "min": 60.0,
    "h": 3600.0,
}
_DISTANCE = {"": 1.0, "mm": 1e-3, "cm": 1e-2, "m": 1.0, "km": 1e3}
_SPEED = {"": 1.0, "m/s": 1.0, "cm/s": 1e-2, "km/h": 1000.0 / 3600.0}
_RATE = {"": 1.0, "%/s": 1.0, "%/min": 1.0 / 60.0, "%/h": 1.0 / 3600.0}


def _parse(
    value: object,
    units: dict[str, float] | dict[str, int],
    what: str,
    example: str,
    *,
    signed: bool,
) -> float:
    """Shared parser: number or `<number><unit>` -> value in the base unit."""
    wrong = ValueError(f"expected {what} such as {example}, got {shown(value)}")
    if isinstance(value, bool):
        raise wrong
    if isinstance(value, int | float):
        if isinstance(value, int) and abs(value) > 2**1000:
            raise wrong  # float() of it would overflow
        number, factor = float(value), 1.0
    elif isinstance(value, str):
        match = _QUANTITY.match(value)
        if match is None:
            raise wrong
        unit = match.group(2).lower()
        if unit not in units:
            raise wrong
        number, factor = float(match.group(1)), float(units[unit])
    else:
        raise wrong
    result = number * factor  # floats: an overflow is inf, refused below
    if not math.isfinite(result) or (not signed and result < 0):
        raise wrong
    return result


def parse_size(value: object) -> int:
    """`500MB`, `2GB`, `512MiB`, `1.5G`, `1024` -> bytes (MB = 1000^2, MiB = 1024^2)."""
    return round(_parse(value, _SIZE, "a size", "500MB", signed=False))


def parse_percent(value: object) -> float:
    """`80%` or `80` -> 80.0."""
    return _parse(value, _PERCENT, "a percentage", "80%", signed=True)


def parse_power(value: object) -> float:
    """`-52.5dBm` or `-52.5` -> -52.5 (dBm)."""
    return _parse(value, _POWER, "a power", "-52.5dBm", signed=True)


def parse_db(value: object) -> float:
    """`1dB` or `1` -> 1.0 (a relative level in dB, e.g. RSSI noise)."""
    return _parse(value, _DB, "a level in dB", "1dB", signed=True)


def parse_duration(value: object) -> float:
    """`6s`, `20ms`, `1.5min`, `2h`, `250us`, `6` -> seconds."""
    return _parse(value, _DURATION, "a duration", "6s", signed=False)


def parse_offset(value: object) -> float:
    """`-1h`, `90s`, `-250ms`, `0` -> seconds, either sign (a clock's error)."""
    return _parse(value, _DURATION, "a time offset", "-1h", signed=True)


def parse_distance(value: object) -> float:
    """`30m`, `2.5km`, `40cm`, `30` -> metres."""
    return _parse(value, _DISTANCE, "a distance", "30m", signed=False)


def parse_speed(value: object) -> float:
    """`0.5m/s`, `3km/h`, `0.5` -> metres per second."""
    return _parse(value, _SPEED, "a speed", "0.5m/s", signed=False)


def parse_rate(value: object) -> float:
    """`2%/min`, `0.5%/s`, `0.5` -> percent per second (negative means rising, e.g. charging)."""
    return _parse(value, _RATE, "a rate", "2%/min", signed=True)


def format_size(n: int) -> str:
    """Bytes as people read them: 200000000 -> '200MB', 1536 -> '1.536KB' (powers of 1000)."""
    for unit, factor in (("TB", 1000**4), ("GB", 1000**3), ("MB", 1000**2), ("KB", 1000)):
        if abs(n) >= factor:
            return f"{n / factor:.4g}{unit}"
    return f"{n}B"
