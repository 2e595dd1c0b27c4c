"""Link quality to each peer, estimated from the gossip core's direct probes.

How it works: the gossip core reports each direct probe's outcome as (peer, rtt or None). Per
peer a `LinkEstimator` keeps
- smoothed RTT, as TCP's SRTT (RFC 6298): srtt += (rtt - srtt) / 8, the first sample taken as is;
- jitter, as RTP's interarrival jitter (RFC 3550 6.4.1) applied to RTT samples:
  D = rtt_i - rtt_(i-1) over consecutive acknowledged probes, J += (|D| - J) / 16, J starting at 0;
- loss, the fraction of lost probes among the last 20 outcomes, ignoring outcomes older than
  30 s (so a link that recovered does not carry old losses forever when probes are sparse).
Until a first ack there is no RTT, so `stats()` is None. `LinkTable` holds one estimator per
peer, and `summary()` turns them into the O(1) `LinkSummary` a record carries: per metric the
value a strict majority of the measured links reach or pass (the (n//2 + 1)-th worst), and the
links at or past the given bounds, the worst `MAX_LISTED` of them exactly (a listed link stays
listed until well inside them: `STAY_LISTED`). Time is always passed
in; nothing here reads a clock.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Collection

from sdrpeer.record.robot import MAX_LISTED, LinkBounds, LinkStats, LinkSummary

SRTT_GAIN = 1 / 8
"""Weight of a new RTT sample in the smoothed RTT (TCP's alpha)."""
JITTER_GAIN = 1 / 16
"""Weight of a new |D| in the jitter (RFC 3550)."""
LOSS_WINDOW = 20
"""Probe outcomes the loss rate is computed over."""
LOSS_MAX_AGE = 30.0
"""Outcomes older than this many seconds no longer count towards loss."""


class LinkEstimator:
    """RTT, jitter and loss of the link to one peer."""

    def __init__(self, window: int = LOSS_WINDOW, max_age: float = LOSS_MAX_AGE) -> None:
        self.max_age = max_age
        self.srtt_ms: float | None = None
        self.jitter_ms = 0.0
        self.last_rtt_ms: float | None = None
        self.probes = 0
        self.last_probe: float | None = None
        self._outcomes: deque[tuple[float, bool]] = deque(maxlen=window)
        """(time, lost) of the most recent probe outcomes."""

    def on_probe(self, now: float) -> None:
        """A probe was sent to the peer (its outcome comes later)."""
        self.probes += 1
        self.last_probe = now
        self._prune(now)

    def on_ack(self, rtt_s: float, now: float) -> None:
        """A probe was acknowledged after `rtt_s` seconds."""
        if not math.isfinite(rtt_s) or rtt_s < 0:
            raise ValueError(f"rtt must be a finite number of seconds >= 0, got {rtt_s!r}")
        rtt = rtt_s * 1000.0
        if self.srtt_ms is None:
            self.srtt_ms = rtt
        else:
            self.srtt_ms += (rtt - self.srtt_ms) * SRTT_GAIN
        if self.last_rtt_ms is not None:
            d = rtt - self.last_rtt_ms
            self.jitter_ms += (abs(d) - self.jitter_ms) * JITTER_GAIN
        self.last_rtt_ms = rtt
        self._outcomes.append((now, False))
        self._prune(now)

    def on_lost(self, now: float) -> None:
        """A probe got no direct ack in time."""
        self._outcomes.append((now, True))
        self._prune(now)

    def _prune(self, now: float) -> None:
        """Drop outcomes older than max_age."""
        while self._outcomes and self._outcomes[0][0] < now - self.max_age:
            self._outcomes.popleft()

    def loss(self, now: float | None = None) -> float:
        """Fraction of lost probes in the window (0.0 when it is empty)."""
        if now is not None:
            self._prune(now)
        if not self._outcomes:
            return 0.0
        return sum(lost for _, lost in self._outcomes) / len(self._outcomes)

    def stats(self, now: float | None = None) -> LinkStats | None:
        """Current estimates, or None before the first ack; `now` also ages out old outcomes."""
        if self.srtt_ms is None:
            return None
        return LinkStats(rtt_ms=self.srtt_ms, jitter_ms=self.jitter_ms, loss=self.loss(now))


class LinkTable:
    """One `LinkEstimator` per peer, fed with probe outcomes."""

    def __init__(self, window: int = LOSS_WINDOW, max_age: float = LOSS_MAX_AGE) -> None:
        self.window = window
        self.max_age = max_age
        self._peers: dict[str, LinkEstimator] = {}
        self._listed: set[str] = set()

    def estimator(self, peer: str) -> LinkEstimator:
        """The peer's estimator, created on first use."""
        est = self._peers.get(peer)
        if est is None:
            est = self._peers[peer] = LinkEstimator(self.window, self.max_age)
        return est

    def observe(self, peer: str, rtt_s: float | None, now: float) -> None:
        """One direct-probe outcome: rtt in seconds, or None when the probe was lost."""
        est = self.estimator(peer)
        if rtt_s is None:
            est.on_lost(now)
        else:
            est.on_ack(rtt_s, now)

    def forget(self, peer: str) -> None:
        """Drop a peer (it left or was reaped)."""
        self._peers.pop(peer, None)

    def peers(self) -> list[str]:
        """Peers with an estimator, sorted."""
        return sorted(self._peers)

    def summary(self, now: float | None, bounds: LinkBounds) -> LinkSummary:
        """The O(1) summary of every measured link (see `summarize`; the links it listed last
        time stay listed until well inside the bounds)."""
        made = summarize(self.snapshot(now), bounds, self._listed)
        self._listed = set(made.listed)
        return made

    def snapshot(self, now: float | None = None) -> dict[str, LinkStats]:
        """Peer -> stats for every peer with at least one ack, sorted by peer."""
        out = {}
        for peer in sorted(self._peers):
            stats = self._peers[peer].stats(now)
            if stats is not None:
                out[peer] = stats
        return out


def majority_worst(values: list[float]) -> float:
    """The value a strict majority of `values` reach or pass, higher being worse: the
    (n//2 + 1)-th highest (one outlier cannot move it; a majority can)."""
    return sorted(values, reverse=True)[len(values) // 2]


STAY_LISTED = 0.8
"""A listed link leaves the list only once every metric is below this share of its bound (a link
hovering at a bound would otherwise be listed and unlisted at every sample)."""


def summarize(
    links: dict[str, LinkStats], bounds: LinkBounds, listed: Collection[str] = ()
) -> LinkSummary:
    """The summary a record carries of `links` (see the module docstring); `listed`: the links
    the previous summary listed (they stay until below `STAY_LISTED` of the bounds)."""
    if not links:
        return LinkSummary(bounds=bounds)
    stats = list(links.values())
    typical = LinkStats(
        rtt_ms=majority_worst([s.rtt_ms for s in stats]),
        jitter_ms=majority_worst([s.jitter_ms for s in stats]),
        loss=majority_worst([s.loss for s in stats]),
    )
    past = [
        (bounds.badness(s), peer)
        for peer, s in links.items()
        if bounds.past(s) or (peer in listed and bounds.past(s, STAY_LISTED))
    ]
    past.sort(key=lambda item: (-item[0], item[1]))
    listed = {peer: links[peer] for _, peer in past[:MAX_LISTED]}
    return LinkSummary(
        peers=len(stats), typical=typical, bad=len(past), bounds=bounds, listed=listed
    )


def distance(a_pos: tuple[float, float] | None, b_pos: tuple[float, float] | None) -> float | None:
    """Straight-line distance in metres, or None if either position is unknown."""
    if a_pos is None or b_pos is None:
        return None
    return math.dist(a_pos, b_pos)
