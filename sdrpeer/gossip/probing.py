"""Failure detection: the SWIM probe round with Lifeguard's nacks and local health.

How it works: every probe interval (stretched by the local-health score) the next peer of a
shuffled round robin is pinged. No ack within the probe timeout: the ping is sent again and k
other peers are asked to ping it (PingReq), answering with a Nack when they cannot reach it. Any
datagram from the target during the round counts as proof of life. No ack by the end of the
round: one more round is run at once (a false suspicion costs a broadcast to every robot and a
refutation back, so squaring its rate under loss is worth one probe interval of detection time);
a second failure makes the target suspect. Missing nacks raise our own health score (our network
may be the problem). Every direct ping's own ack gives an RTT sample; a ping without one counts
as lost. A direct ping also carries our newest vitals revision while the target has not
acknowledged it (an ack of a ping that carried it): each peer gets our measured values from our
own probes, at a cost that does not grow with the fleet, and again after a lost ping.
"""

from __future__ import annotations

from sdrpeer.gossip import formulas
from sdrpeer.gossip.base import FWD_END, PROBE, PROBE_END, PROBE_TIMEOUT, CoreState, Probe
from sdrpeer.gossip.events import (
    ProbeOutcome,
)
from sdrpeer.gossip.messages import (
    ALIVE,
    SUSPECT,
    Ack,
    Addr,
    Nack,
    Ping,
    PingReq,
    Suspect,
    Update,
)


class Probing(CoreState):
    """The probe round, the intermediary's side of indirect probes, and local health."""

    def _start_probe(self) -> None:
        interval = formulas.scaled(self.config.probe_interval, self.health_score)
        self._at(self._now + interval, PROBE, None)
        if self.leaving:
            return
        target = self._ring.next(self.rng, self._peers)
        if target is not None:
            self._probe(target, confirming=False)

    def _probe(self, target: str, *, confirming: bool) -> None:
        cfg = self.config
        probe = Probe(target, confirming)
        self._probing[target] = probe
        self._ping(probe)
        timeout = formulas.scaled(cfg.probe_timeout, self.health_score)
        self._at(self._now + timeout, PROBE_TIMEOUT, probe)
        self._at(
            self._now + formulas.scaled(cfg.probe_interval, self.health_score), PROBE_END, probe
        )

    def _ping(self, probe: Probe) -> int:
        m = self._members[probe.target]
        seq = self._next_seq()
        probe.pings[seq] = self._now
        self._probes[seq] = probe
        vitals = self._my_vitals
        if vitals is not None and self._vitals_acked.get(m.name, (0, 0)) < vitals.key:
            probe.vitals[seq] = vitals.key
            updates = self._piggyback(m, len(vitals.payload) + 16)
        else:
            vitals = None
            updates = self._piggyback(m)
        self._out.append((m.addr, Ping(self.name, seq, m.name, updates, vitals)))
        return seq

    def _probe_timeout(self, probe: Probe) -> None:
        m = self._members.get(probe.target)
        if probe.acked or m is None or m.state not in (ALIVE, SUSPECT):
            return
        seq = self._ping(probe)  # a second direct ping, then k indirect ones
        for name in self._peers.sample(self.rng, self.config.indirect_checks, exclude=m.name):
            req = PingReq(self.name, seq, m.name, m.addr, True, self._take(self._budget))
            self._out.append((self._members[name].addr, req))
            probe.want_nacks += 1

    def _probe_end(self, probe: Probe) -> None:
        for seq in probe.pings:
            self._probes.pop(seq, None)
        for _ in probe.pings:  # every ping whose own ack never came counts as lost
            self._events.append(ProbeOutcome(probe.target, None, self._now))
        probe.pings.clear()
        if self._probing.get(probe.target) is probe:
            del self._probing[probe.target]
        if probe.acked:
            return
        missing = probe.want_nacks - probe.nacks if probe.want_nacks else 1
        self._adjust_health(max(0, missing))
        m = self._members.get(probe.target)
        if m is None or m.state not in (ALIVE, SUSPECT):
            return
        if m.state == ALIVE and not probe.confirming and self.config.confirm_round:
            self._probe(m.name, confirming=True)  # one more round before accusing anyone
            return
        self._merge_suspect(Suspect(m.name, m.incarnation, self.name))

    def _probe_succeeded(self, probe: Probe) -> None:
        if probe.acked:
            return
        probe.acked = True
        self._adjust_health(-1)

    def _on_ping(self, src: Addr, ping: Ping) -> None:
        if ping.target != self.name:
            self._count("misdirected")
            return
        m = self._members.get(ping.sender)
        buddy: list[Update] = []
        if m is not None and m.state != ALIVE:
            buddy.append(self._fact_about(m))
        updates = tuple(buddy) + self._take(self._budget - 64 * len(buddy))
        self._out.append((src, Ack(self.name, ping.seq, updates)))

    def _on_ack(self, ack: Ack) -> None:
        probe = self._probes.get(ack.seq)
        if probe is not None:
            if ack.sender == probe.target:
                sent = probe.pings.pop(ack.seq, None)
                if sent is not None:
                    self._events.append(ProbeOutcome(probe.target, self._now - sent, self._now))
                carried = probe.vitals.pop(ack.seq, None)
                if carried is not None and carried > self._vitals_acked.get(ack.sender, (0, 0)):
                    self._vitals_acked[ack.sender] = carried
            self._probe_succeeded(probe)
            return
        fwd = self._fwd.pop(ack.seq, None)
        if fwd is not None:
            self._out.append((fwd[0], Ack(self.name, fwd[1], self._take(self._budget))))

    def _on_ping_req(self, src: Addr, req: PingReq) -> None:
        seq = self._next_seq()
        self._fwd[seq] = (src, req.seq, req.want_nack)
        m = self._members.get(req.target)
        updates = self._piggyback(m) if m is not None else self._take(self._budget)
        self._out.append((req.target_addr, Ping(self.name, seq, req.target, updates)))
        self._at(self._now + self.config.probe_timeout * 0.8, FWD_END, seq)

    def _fwd_end(self, seq: int) -> None:
        fwd = self._fwd.pop(seq, None)
        if fwd is not None and fwd[2]:
            self._out.append((fwd[0], Nack(self.name, fwd[1])))

    def _adjust_health(self, delta: int) -> None:
        self.health_score = min(max(0, self.health_score + delta), self.config.awareness_max - 1)
