"""`InPortRuntime.deliver_many` (a read's frames at once) does exactly what `deliver` per frame
does: the same values come out in the same order, typed or not, with the same counters, the same
acknowledgements and the same number of frames told to the OnInput listener; whatever the
connection's policy, gaps, replays, restarted senders and wrong shapes among the frames."""

from __future__ import annotations

import random
from typing import Any

import pytest

from sdrpeer.sdk import ConnectorPolicy, Pose
from sdrpeer.sdk.inport import InPortRuntime
from sdrpeer.sdk.typed import message_type

POLICIES = [
    ConnectorPolicy("fifo", 1 << 20, "block"),
    ConnectorPolicy("all", 8, "overwrite"),
    ConnectorPolicy("fifo", 5, "drop"),
    ConnectorPolicy("skip", 16, "overwrite", skip=2),
    ConnectorPolicy("new", 4, "overwrite"),
]
POSE = Pose(1.0, "map", 1.0, 2.0)
WIRE = list(message_type(Pose).flat(POSE))  # type: ignore[union-attr]


class Twin:
    """One port fed by batches, one fed frame by frame, identically configured."""

    def __init__(self, policy: ConnectorPolicy, *, typed: bool, acked: bool) -> None:
        self.sent: dict[str, list[tuple[int, int]]] = {"many": [], "one": []}
        self.told = {"many": 0, "one": 0}
        self.ports: dict[str, InPortRuntime] = {}
        self.keys: dict[str, str] = {}
        for side in ("many", "one"):
            p = InPortRuntime("in", policy, port_type=Pose if typed else None)
            p.connect("c", policy)
            key = "c"
            if acked:
                key = p.attach_stream("c", "s1", 0, self._sender(side))
            p._listener = self._listener(side)
            self.ports[side], self.keys[side] = p, key

    def _sender(self, side: str) -> Any:
        return lambda seq, dropped: self.sent[side].append((seq, dropped))

    def _listener(self, side: str) -> Any:
        def told(n: int) -> None:
            self.told[side] += n

        return told

    def feed(self, frames: list[list[Any]]) -> None:
        self.ports["many"].deliver_many(frames, self.keys["many"])
        one = self.ports["one"]
        for seq, value in frames:
            one.deliver(value, seq, self.keys["one"])

    def take(self, k: int) -> None:
        got = {}
        for side, p in self.ports.items():
            got[side] = [p.get_nowait() for _ in range(min(k, p.qsize()))]
        assert got["many"] == got["one"]

    def check(self) -> None:
        many, one = self.ports["many"], self.ports["one"]
        assert many.counters() == one.counters()
        assert many.qsize() == one.qsize()
        assert many.is_new() == one.is_new()
        assert many.acked(self.keys["many"]) == one.acked(self.keys["one"])
        assert self.told["many"] == self.told["one"]
        if self.sent["one"]:  # the same acknowledgement state reached the sender
            assert self.sent["many"][-1] == self.sent["one"][-1]
            assert sum(d for _, d in self.sent["many"]) == sum(d for _, d in self.sent["one"])


def frames_for(rng: random.Random, start: int, typed: bool) -> tuple[list[list[Any]], int]:
    """A batch: mostly consecutive seqs, sometimes a gap, a replay, a restart, a wrong shape."""
    out: list[list[Any]] = []
    seq = start
    for _ in range(rng.randint(1, 40)):
        roll = rng.random()
        if roll < 0.05:
            seq += rng.randint(2, 5)  # frames lost on the way
        elif roll < 0.08:
            seq = max(0, seq - rng.randint(1, 6))  # a replay (acked) or a restart (not)
        value: Any = list(WIRE) if typed else seq
        if rng.random() < 0.03:
            value = b"not a pose" if typed else [seq]
        out.append([seq, value])
        seq += 1
    return out, seq


@pytest.mark.parametrize("typed", [False, True], ids=["untyped", "typed"])
@pytest.mark.parametrize("acked", [False, True], ids=["plain", "acked"])
@pytest.mark.parametrize("policy", POLICIES, ids=lambda p: f"{p.push}-{p.buffer}-{p.full}")
def test_a_batch_is_delivered_as_frame_by_frame(
    policy: ConnectorPolicy, acked: bool, typed: bool
) -> None:
    rng = random.Random(f"{policy}-{acked}-{typed}")
    twin = Twin(policy, typed=typed, acked=acked)
    seq = 0
    for _ in range(200):
        frames, seq = frames_for(rng, seq, typed)
        twin.feed(frames)
        twin.check()
        twin.take(rng.randint(0, 30))
        twin.check()
    twin.take(1 << 20)
    twin.check()


def test_the_fast_path_queues_a_whole_batch_and_wakes_once() -> None:
    p = InPortRuntime("in", ConnectorPolicy("fifo", 64, "block"), port_type=Pose)
    told: list[int] = []
    p._listener = told.append
    p.deliver_many([[s, list(WIRE)] for s in range(10)], "c")
    assert told == [10]  # one wake-up for the read, not ten
    assert p.qsize() == 10
    assert p.get_nowait() == POSE
    # a batch that would not fit goes frame by frame: the policy decides per frame
    p.deliver_many([[s, list(WIRE)] for s in range(10, 70)], "c")
    assert told[1:] == [1] * 60
