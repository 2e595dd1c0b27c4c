"""Which refusals of a sender's connection are told: the first at once, then one per `every`
seconds with the count since, a new connection on its own clock, and the end of the trouble
once (sdrpeer.dataplane.refusals; literal times)."""

from __future__ import annotations

from sdrpeer.dataplane.refusals import DialRefusals, RefusalWatch, Told


def test_refusals_are_told_once_then_at_most_every_period_with_their_count() -> None:
    w = RefusalWatch(every=30.0)
    assert w.refused(100.0, "c1", "unknown in-port 'x'") == Told("c1", "unknown in-port 'x'", 1)
    assert w.refused(101.0, "c1", "unknown in-port 'x'") is None
    assert w.refused(103.0, "c2", "bad key") == Told("c2", "bad key", 1)  # its own clock
    assert w.refused(129.9, "c1", "unknown in-port 'x'") is None
    assert w.refused(130.0, "c1", "type mismatch") == Told("c1", "type mismatch", 3)
    assert w.refused(131.0, "c1", "type mismatch") is None
    assert w.accepted("c1") == Told("c1", None, 1)  # over, with the one not told yet
    assert w.accepted("c1") is None  # said once
    assert w.refused(132.0, "c1", "again") == Told("c1", "again", 1)  # a new spell: at once
    assert w.accepted("c9") is None  # never refused: nothing to say
    w.forget("c2")
    assert w.refused(133.0, "c2", "bad key") == Told("c2", "bad key", 1)


def test_a_dialing_end_counts_its_refusals_and_tells_each_and_the_end_once() -> None:
    told: list[str | None] = []
    dials = DialRefusals("c1")
    dials.through()  # never refused: nothing to tell
    dials.on_refused = told.append
    dials.refused("bad key")
    dials.refused("bad key")
    assert (dials.count, dials.last) == (2, "bad key")
    dials.through()
    dials.through()
    assert (dials.count, dials.last) == (2, None)
    assert told == ["bad key", "bad key", None]

    def broken(reason: str | None) -> None:
        raise RuntimeError("a broken hook")

    dials.on_refused = broken
    dials.refused("again")  # logged, not raised: the dialing goes on
    assert dials.count == 3
