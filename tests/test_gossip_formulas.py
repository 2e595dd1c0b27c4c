"""The protocol's formulas, table-driven."""

from __future__ import annotations

import math

import pytest

from sdrpeer.gossip import formulas


@pytest.mark.parametrize(
    ("mult", "n", "expected"),
    [
        (4, 1, 4),
        (4, 3, 4),
        (4, 9, 4),
        (4, 10, 8),
        (4, 99, 8),
        (4, 100, 12),
        (4, 1000, 16),
        (3, 1000, 12),
    ],
)
def test_retransmit_limit(mult: int, n: int, expected: int) -> None:
    assert formulas.retransmit_limit(mult, n) == expected


@pytest.mark.parametrize(
    ("mult", "n", "interval", "expected"),
    [
        (4, 1, 0.15, 0.6),
        (4, 3, 0.15, 0.6),
        (4, 10, 0.15, 0.6),
        (4, 100, 0.15, 1.2),
        (4, 1000, 0.2, 2.4),
    ],
)
def test_suspicion_min_timeout(mult: float, n: int, interval: float, expected: float) -> None:
    assert formulas.suspicion_min_timeout(mult, n, interval) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("mult", "n", "expected"), [(4, 3, 0), (4, 4, 2), (4, 10, 2), (6, 10, 4), (6, 5, 0), (2, 10, 0)]
)
def test_confirmations_wanted(mult: float, n: int, expected: int) -> None:
    assert formulas.suspicion_confirmations_wanted(mult, n) == expected


@pytest.mark.parametrize(
    ("c", "k", "expected"),
    [
        (0, 2, 3.0),
        (1, 2, 3.0 - 2.0 * math.log(2) / math.log(3)),
        (2, 2, 1.0),
        (5, 2, 1.0),  # never below min
        (0, 0, 1.0),  # no confirmations expected: min at once
    ],
)
def test_suspicion_timeout_shrinks_with_confirmations(c: int, k: int, expected: float) -> None:
    assert formulas.suspicion_timeout(c, k, 1.0, 3.0) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("n", "expected"), [(1, 5.0), (32, 5.0), (33, 10.0), (64, 10.0), (65, 15.0), (1000, 30.0)]
)
def test_push_pull_scale(n: int, expected: float) -> None:
    assert formulas.push_pull_scale(5.0, n) == pytest.approx(expected)


def test_scaled_by_health() -> None:
    assert formulas.scaled(0.15, 0) == pytest.approx(0.15)
    assert formulas.scaled(0.15, 3) == pytest.approx(0.6)
