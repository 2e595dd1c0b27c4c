"""Link estimators: SRTT, RFC 3550 jitter checked by hand, loss window by count and by age."""

from __future__ import annotations

import math

import pytest

from sdrpeer.monitor.links import LinkEstimator, LinkTable, distance, majority_worst, summarize
from sdrpeer.record.robot import MAX_LISTED, LinkBounds, LinkStats


def test_no_stats_before_first_ack() -> None:
    est = LinkEstimator()
    assert est.stats() is None
    est.on_probe(0.0)
    est.on_lost(0.5)
    assert est.stats() is None
    assert est.loss() == 1.0
    assert est.probes == 1


def test_srtt_and_jitter_against_a_hand_computed_sequence() -> None:
    # RTTs 10, 14, 12, 20 ms:
    #   srtt: 10 -> 10 + 4/8 = 10.5 -> 10.5 + 1.5/8 = 10.6875 -> 10.6875 + 9.3125/8 = 11.8515625
    #   D:        4        -2         8
    #   J:  0 -> 4/16 = 0.25 -> 0.25 + (2 - 0.25)/16 = 0.359375
    #         -> 0.359375 + (8 - 0.359375)/16 = 0.8369140625
    est = LinkEstimator()
    expected = [(10.0, 0.0), (10.5, 0.25), (10.6875, 0.359375), (11.8515625, 0.8369140625)]
    for t, (rtt, (srtt, jitter)) in enumerate(zip([10, 14, 12, 20], expected, strict=True)):
        est.on_ack(rtt / 1000, float(t))
        s = est.stats()
        assert s is not None
        assert s.rtt_ms == pytest.approx(srtt, abs=1e-9)
        assert s.jitter_ms == pytest.approx(jitter, abs=1e-9)
        assert s.loss == 0.0


def test_jitter_spans_lost_probes() -> None:
    est = LinkEstimator()
    est.on_ack(0.010, 0.0)
    est.on_lost(1.0)
    est.on_lost(2.0)
    est.on_ack(0.026, 3.0)  # D = 16 ms against the last *acknowledged* probe
    s = est.stats()
    assert s is not None
    assert s.jitter_ms == pytest.approx(1.0)
    assert s.loss == pytest.approx(0.5)


def test_constant_rtt_has_no_jitter() -> None:
    est = LinkEstimator()
    for t in range(50):
        est.on_ack(0.005, float(t))
    assert est.stats() == LinkStats(rtt_ms=5.0, jitter_ms=0.0, loss=0.0)


def test_loss_over_the_last_20_outcomes() -> None:
    est = LinkEstimator()
    t = 0.0
    for _ in range(10):
        est.on_lost(t)
        t += 0.2
    for _ in range(15):
        est.on_ack(0.004, t)
        t += 0.2
    assert est.loss() == pytest.approx(5 / 20)  # only the last 5 losses are still in the window
    for _ in range(5):
        est.on_ack(0.004, t)
        t += 0.2
    assert est.loss() == 0.0


def test_outcomes_older_than_30s_do_not_count() -> None:
    est = LinkEstimator()
    est.on_ack(0.004, 0.0)
    for t in (1.0, 2.0, 3.0):
        est.on_lost(t)
    assert est.loss(10.0) == pytest.approx(0.75)
    est.on_ack(0.004, 31.5)  # 0.0 and 1.0 are now older than 30 s
    assert est.loss() == pytest.approx(2 / 3)
    s = est.stats(40.0)  # only 31.5 remains
    assert s is not None
    assert s.loss == 0.0


def test_bad_rtt_is_refused() -> None:
    with pytest.raises(ValueError, match="rtt must be"):
        LinkEstimator().on_ack(-0.001, 0.0)
    with pytest.raises(ValueError, match="rtt must be"):
        LinkEstimator().on_ack(math.nan, 0.0)


def test_link_table() -> None:
    table = LinkTable()
    table.observe("robot-2", 0.004, 0.0)
    table.observe("robot-3", None, 0.0)
    table.observe("robot-3", 0.010, 1.0)
    table.observe("robot-4", None, 1.0)  # never acked: no stats yet
    snap = table.snapshot(2.0)
    assert list(snap) == ["robot-2", "robot-3"]
    assert snap["robot-2"] == LinkStats(rtt_ms=4.0, jitter_ms=0.0, loss=0.0)
    assert snap["robot-3"].loss == 0.5
    assert table.peers() == ["robot-2", "robot-3", "robot-4"]
    table.forget("robot-2")
    table.forget("nobody")
    assert list(table.snapshot()) == ["robot-3"]


@pytest.mark.parametrize(
    ("a", "b", "expected"),
    [((0.0, 0.0), (3.0, 4.0), 5.0), ((1.0, 1.0), (1.0, 1.0), 0.0), (None, (1.0, 1.0), None)],
)
def test_distance(
    a: tuple[float, float] | None, b: tuple[float, float] | None, expected: float | None
) -> None:
    assert distance(a, b) == expected
    assert distance(b, a) == expected


def test_majority_worst_is_what_more_than_half_reach() -> None:
    assert majority_worst([0.4]) == 0.4
    assert majority_worst([0.0, 0.4]) == 0.0
    assert majority_worst([0.0, 0.4, 0.5]) == 0.4
    assert majority_worst([0.4, 0.5, 0.0, 0.6]) == 0.4


def test_summary_of_fifty_links() -> None:
    bounds = LinkBounds(rtt_ms=50.0, jitter_ms=10.0, loss=0.05)
    links = {f"robot-{k}": LinkStats(2.0 + k / 10, 0.5, 0.0) for k in range(50)}
    links["robot-7"] = LinkStats(80.0, 0.5, 0.0)  # slow
    links["robot-8"] = LinkStats(3.0, 0.5, 0.3)  # lossy: worse (0.3 / 0.05 = 6 > 80 / 50)
    links["robot-9"] = LinkStats(3.0, 10.0, 0.0)  # jitter exactly at the bound: listed
    s = summarize(links, bounds)
    assert s.peers == 50
    assert s.bad == 3
    assert s.complete
    assert list(s.listed) == ["robot-8", "robot-7", "robot-9"]  # worst first
    assert s.typical is not None
    assert s.typical.loss == 0.0
    assert 4.0 < s.typical.rtt_ms < 5.0
    many = {f"robot-{k}": LinkStats(3.0, 0.5, 0.1 + k / 1000) for k in range(20)}
    t = summarize(many, bounds)
    assert t.bad == 20
    assert len(t.listed) == MAX_LISTED
    assert not t.complete
    assert next(iter(t.listed)) == "robot-19"
    assert summarize({}, bounds).typical is None


def test_link_table_summary() -> None:
    table = LinkTable()
    for t in range(4):
        table.observe("robot-2", 0.002, float(t))
        table.observe("robot-3", None if t % 2 else 0.004, float(t))
    s = table.summary(4.0, LinkBounds(loss=0.2))
    assert s.peers == 2
    assert list(s.listed) == ["robot-3"]
    assert s.listed["robot-3"].loss == 0.5


def test_a_listed_link_stays_until_well_inside_its_bounds() -> None:
    bounds = LinkBounds(jitter_ms=10.0)
    s = summarize({"a": LinkStats(1.0, 12.0, 0.0)}, bounds)
    assert list(s.listed) == ["a"]
    hovering = {"a": LinkStats(1.0, 9.0, 0.0)}
    assert list(summarize(hovering, bounds, listed={"a"}).listed) == ["a"]  # 9 >= 0.8 x 10
    assert summarize(hovering, bounds).listed == {}  # never listed: 9 < 10 is inside
    assert summarize({"a": LinkStats(1.0, 7.9, 0.0)}, bounds, listed={"a"}).listed == {}
