"""The agent's overflow warnings with literal times: at once when a port starts losing frames
to full buffers, then at most one per `every` seconds with what was lost in between, afresh
after a quiet spell and after the host restarted; nothing for ports that lose nothing."""

from __future__ import annotations

from sdrpeer.runtime.overflow import Overflow, OverflowWatch


def ports(**overflowed: int) -> dict[str, dict[str, int]]:
    return {port: {"frames_out": 100, "overflowed": n} for port, n in overflowed.items()}


def test_a_port_that_starts_overflowing_is_warned_about_at_once_then_every_30_s() -> None:
    watch = OverflowWatch(every=30.0)
    assert watch.feed(0.0, "Cam", ports(image=0, info=0)) == []
    assert watch.feed(1.0, "Cam", ports(image=5, info=0)) == [Overflow("Cam", "image", 5, 5)]
    assert watch.feed(2.0, "Cam", ports(image=9, info=0)) == []  # still losing: held back
    assert watch.feed(30.9, "Cam", ports(image=20, info=0)) == []
    assert watch.feed(31.0, "Cam", ports(image=25, info=0)) == [Overflow("Cam", "image", 20, 25)]
    assert watch.feed(100.0, "Cam", ports(image=25, info=0)) == []  # quiet: nothing
    # after a quiet spell longer than `every`, the next loss is told at once
    assert watch.feed(101.0, "Cam", ports(image=26, info=0)) == [Overflow("Cam", "image", 1, 26)]


def test_a_restarted_host_counts_afresh_and_ports_are_independent() -> None:
    watch = OverflowWatch(every=30.0)
    assert watch.feed(0.0, "Cam", ports(image=50)) == [Overflow("Cam", "image", 50, 50)]
    # the host restarted: its counters began again at 0 and it lost 3 since
    assert watch.feed(40.0, "Cam", ports(image=3)) == [Overflow("Cam", "image", 3, 3)]
    assert watch.feed(41.0, "Det", ports(alarm=1)) == [Overflow("Det", "alarm", 1, 1)]
    watch.keep({"Det"})  # Cam is gone
    assert watch.feed(42.0, "Cam", ports(image=3)) == [Overflow("Cam", "image", 3, 3)]
