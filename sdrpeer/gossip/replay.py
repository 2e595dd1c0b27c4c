"""Replay protection: a freshness window plus a per-sender sliding window of sequence numbers.

How it works (as IPsec's anti-replay window): for each sender we keep its highest seq and a
bitmap of the `REPLAY_WINDOW` seqs below it. A datagram is refused as "stale" when its timestamp
is older than the freshness window before `now` (the cluster time: sdrpeer.gossip.wire's codec keeps
it at the newest authenticated timestamp it has seen, so a datagram dated *later* than now is
not refused — a replay can only be older), and as "replayed" when its seq was seen already or
is older than the window. The windows live in memory only, so a restarted robot would take again
what was sent to its previous life: `life_start_ms` (set when this life begins) refuses as
"stale" anything stamped before it. Time is passed in; at most `max_senders` senders are tracked
(the least recently seen is forgotten first), so a flood of forged names cannot exhaust memory.

Time (`ClusterClock`): robots far from any NTP server cannot keep their clocks within the window
of each other, so the codec keeps a *cluster time*: its own wall clock plus an offset that only
grows, to the newest timestamp of any authenticated datagram accepted (a hybrid logical clock on
wall time: the fleet runs on its fastest clock). Datagrams are stamped with it; the agent keeps
the offset in its data directory, so a restarted robot does not fall back to its own clock. A
robot whose clock is behind adopts the fleet's time with the first datagram it hears; a replay,
always older than the newest traffic, stays stale. Without keys nothing moves the time and a
datagram more than the window in the future is refused too; a timestamp past `MAX_TS_MS` is
always refused (the time must stay encodable).
"""

from __future__ import annotations

from collections import OrderedDict

MAX_TS_MS = 1 << 52
"""Timestamps beyond this (year ~142,000) are refused."""
REPLAY_WINDOW = 1024
"""How many seqs below a sender's highest one are remembered (older ones are rejected)."""
_WINDOW_MASK = (1 << REPLAY_WINDOW) - 1


class ReplayGuard:
    """Rejects stale timestamps and repeated or too old per-sender seqs (no clock of its own)."""

    def __init__(self, freshness_s: float = 30.0, max_senders: int = 4096) -> None:
        if freshness_s <= 0 or max_senders < 1:
            raise ValueError("freshness_s must be > 0 and max_senders >= 1")
        self.freshness_ms = int(freshness_s * 1000)
        self.max_senders = max_senders
        self.life_start_ms = 0
        """Cluster time this robot's life began (`Codec.begin_life`): anything stamped earlier
        was sent to an earlier life, whose windows are gone."""
        # sender -> [highest seq, bitmap]; bit i set = seq (highest - i) was accepted.
        self._senders: OrderedDict[str, list[int]] = OrderedDict()

    def __len__(self) -> int:
        """Number of senders tracked."""
        return len(self._senders)

    def newer(self, sender: str, seq: int) -> bool:
        """Whether `seq` is above every seq accepted from `sender` (True for a sender not
        tracked): a replay of recorded traffic never is once what followed it was accepted."""
        state = self._senders.get(sender)
        return state is None or seq > state[0]

    def check(self, sender: str, seq: int, ts_ms: int, now_ms: int) -> str | None:
        """None if acceptable (the seq is then recorded), else "stale" or "replayed"."""
        if now_ms - ts_ms > self.freshness_ms or ts_ms < self.life_start_ms:
            return "stale"
        state = self._senders.get(sender)
        if state is None:
            if len(self._senders) >= self.max_senders:
                self._senders.popitem(last=False)
            self._senders[sender] = [seq, 1]
            return None
        top, bits = state
        if seq > top:
            shift = seq - top
            state[0] = seq
            state[1] = ((bits << shift) | 1) & _WINDOW_MASK if shift < REPLAY_WINDOW else 1
        else:
            offset = top - seq
            if offset >= REPLAY_WINDOW or (bits >> offset) & 1:
                return "replayed"
            state[1] = bits | (1 << offset)
        self._senders.move_to_end(sender)
        return None


class ClusterClock:
    """This robot's cluster time (see the module docstring); no clock of its own."""

    __slots__ = ("offset_ms",)

    def __init__(self) -> None:
        self.offset_ms = 0
        """How far the cluster time is ahead of this robot's wall clock (only grows)."""

    def now_ms(self, wall: float) -> int:
        """The cluster time, in ms, at wall-clock time `wall` (seconds)."""
        return int(wall * 1000) + self.offset_ms

    @staticmethod
    def too_new(ts_ms: int, now_ms: int, window_ms: int, *, authenticated: bool) -> bool:
        """True for a timestamp to refuse for being in the future: past `MAX_TS_MS`, or, when
        nothing vouches for it, more than the window ahead."""
        return ts_ms > MAX_TS_MS or (not authenticated and ts_ms - now_ms > window_ms)

    def observe(self, ts_ms: int, now_ms: int) -> bool:
        """An authenticated datagram of `ts_ms` was accepted at `now_ms`: True if it moved the
        cluster time on."""
        if ts_ms <= now_ms:
            return False
        self.offset_ms += ts_ms - now_ms
        return True
