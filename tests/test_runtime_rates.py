"""Per-port rates from two heartbeats (sdrpeer.runtime.rates), as a table."""

from __future__ import annotations

import pytest

from sdrpeer.runtime.rates import port_rates

A = {"out": {"frames_out": 100, "bytes_out": 1000}}
CASES = [
    ("grows", A, {"out": {"frames_out": 150, "bytes_out": 1500}}, 0.5,
     {"out": {"frames_out_per_s": 100.0, "bytes_out_per_s": 1000.0}}),
    ("still", A, A, 0.5, {"out": {"frames_out_per_s": 0.0, "bytes_out_per_s": 0.0}}),
    ("a new host counts from 0", A, {"out": {"frames_out": 3, "bytes_out": 30}}, 0.5, {}),
    ("a port not there before", {}, A, 0.5, {}),
    ("no time between", A, A, 0.0, {}),
    ("only counters both carry", {"inp": {"frames_in": 1}},
     {"inp": {"frames_in": 5, "bytes_in": 9}}, 2.0, {"inp": {"frames_in_per_s": 2.0}}),
    ("counters that are not rated", {"inp": {"lost": 1}}, {"inp": {"lost": 9}}, 1.0, {}),
]  # fmt: skip


@pytest.mark.parametrize(("case", "before", "after", "seconds", "want"), CASES)
def test_port_rates(case, before, after, seconds, want):
    assert port_rates(before, after, seconds) == want, case
