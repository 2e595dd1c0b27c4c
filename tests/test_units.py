"""Table-driven tests for sdrpeer.units."""

from __future__ import annotations

import re
from collections.abc import Callable

import pytest

from sdrpeer import units

SIZES = [
    ("500MB", 500_000_000),
    ("2GB", 2_000_000_000),
    ("512MiB", 512 * 1024**2),
    ("1.5G", 1_500_000_000),
    ("1024", 1024),
    (1024, 1024),
    ("4 GiB", 4 * 1024**3),
    ("500mb", 500_000_000),
    ("10KB", 10_000),
    ("10KiB", 10_240),
    ("0", 0),
    ("100B", 100),
    ("2Gi", 2 * 1024**3),
]


@pytest.mark.parametrize(("text", "expected"), SIZES)
def test_parse_size(text: object, expected: int) -> None:
    assert units.parse_size(text) == expected
    assert isinstance(units.parse_size(text), int)


@pytest.mark.parametrize(
    ("fn", "text", "expected"),
    [
        (units.parse_percent, "80%", 80.0),
        (units.parse_percent, "12.5 %", 12.5),
        (units.parse_percent, 80, 80.0),
        (units.parse_power, "-52.5dBm", -52.5),
        (units.parse_power, "-47 dBm", -47.0),
        (units.parse_power, -45, -45.0),
        (units.parse_db, "1dB", 1.0),
        (units.parse_duration, "6s", 6.0),
        (units.parse_duration, "20ms", 0.02),
        (units.parse_duration, "1.5min", 90.0),
        (units.parse_duration, "2h", 7200.0),
        (units.parse_duration, "250us", 0.00025),
        (units.parse_duration, "250µs", 0.00025),
        (units.parse_duration, 107, 107.0),
        (units.parse_distance, "30m", 30.0),
        (units.parse_distance, "2.5km", 2500.0),
        (units.parse_distance, "40cm", 0.4),
        (units.parse_distance, 3.5, 3.5),
        (units.parse_speed, "0.5m/s", 0.5),
        (units.parse_speed, "3.6km/h", 1.0),
        (units.parse_rate, "2%/min", 2.0 / 60.0),
        (units.parse_rate, "0.5%/s", 0.5),
        (units.parse_rate, "36%/h", 0.01),
        (units.parse_rate, "-1%/s", -1.0),
    ],
)
def test_parse_quantities(fn: Callable[[object], float], text: object, expected: float) -> None:
    assert fn(text) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(
    ("fn", "value", "message"),
    [
        (units.parse_size, "5XB", "expected a size such as 500MB, got '5XB'"),
        (units.parse_size, "lots", "expected a size such as 500MB, got 'lots'"),
        (units.parse_size, "-5MB", "expected a size such as 500MB, got '-5MB'"),
        (units.parse_size, True, "expected a size such as 500MB, got True"),
        (units.parse_size, [1], "expected a size such as 500MB, got [1]"),
        (units.parse_size, None, "expected a size such as 500MB, got None"),
        (units.parse_percent, "80 percent", "expected a percentage such as 80%, got '80 percent'"),
        (units.parse_power, "-52.5dB", "expected a power such as -52.5dBm, got '-52.5dB'"),
        (units.parse_db, "1dBm", "expected a level in dB such as 1dB, got '1dBm'"),
        (units.parse_duration, "5m", "expected a duration such as 6s, got '5m'"),
        (units.parse_duration, "-1s", "expected a duration such as 6s, got '-1s'"),
        (units.parse_duration, float("nan"), "expected a duration such as 6s, got nan"),
        (units.parse_duration, "inf", "expected a duration such as 6s, got 'inf'"),
        (units.parse_distance, "3 miles", "expected a distance such as 30m, got '3 miles'"),
        (units.parse_speed, "1m", "expected a speed such as 0.5m/s, got '1m'"),
        (units.parse_rate, "2%", "expected a rate such as 2%/min, got '2%'"),
        (units.parse_rate, "", "expected a rate such as 2%/min, got ''"),
        (  # a huge value: its first 60 characters and its length (issue 30)
            units.parse_size,
            "9" * 200_224 + "XB",
            f"expected a size such as 500MB, got '{'9' * 60}'... (200,226 characters)",
        ),
        (
            units.parse_percent,
            [50] * 100_000,
            f"expected a percentage such as 80%, got {'[' + '50, ' * 14 + '50,'}... "
            "(400,000 characters)",
        ),
    ],
)
def test_errors_name_the_kind_and_the_value(
    fn: Callable[[object], float], value: object, message: str
) -> None:
    with pytest.raises(ValueError, match="^" + re.escape(message) + "$"):
        fn(value)


@pytest.mark.parametrize(
    ("n", "text"),
    [(200_000_000, "200MB"), (1536, "1.536KB"), (999, "999B"), (4_000_000_000, "4GB")],
)
def test_format_size(n: int, text: str) -> None:
    assert units.format_size(n) == text
