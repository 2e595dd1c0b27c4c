"""When a robot's record is worth publishing before its heartbeat.

How it works: a deadband around the values last published: cpu 5 points, free memory 1 % of
capacity or 16 MiB, battery 1 point, RSSI 2 dB (threshold crossings go out at once as traps
anyway), link RTT 1 ms or 25 %, jitter 1 ms or 50 %, loss 5 points, and any change of identity,
position, capacity, the set of links, or an instance's name, state or role (an instance's cpu
and memory use the same bands as the robot's). Fixed buckets would flap at their edges on
noise; a deadband only moves when the value really does. Without it every robot would publish a
new version every second, and at N robots each version is sent 4*ceil(log10(N+1)) times by
every robot.
"""

from __future__ import annotations

from sdrpeer.record import RobotRecord


def worth_publishing(last: RobotRecord | None, new: RobotRecord) -> bool:
    """Whether `new` differs enough from the last published record to publish before the
    heartbeat: a deadband around the published values (not fixed buckets, whose edges would
    flap on noise). Sampling noise must not make every robot publish every second.
    """
    if last is None:
        return True
    a, b = last.metrics, new.metrics
    if (last.api, last.priority, a.mem_total, a.pos) != (new.api, new.priority, b.mem_total, b.pos):
        return True
    if _instances_moved(last, new):
        return True
    if abs(a.cpu_pct - b.cpu_pct) >= 5.0 or abs(a.mem_free - b.mem_free) >= max(
        16 << 20, b.mem_total // 100
    ):
        return True
    if _moved(a.battery_pct, b.battery_pct, 1.0) or _moved(a.rssi_dbm, b.rssi_dbm, 2.0):
        return True
    if last.links.keys() != new.links.keys():
        return True
    for peer, link in new.links.items():
        old = last.links[peer]
        if abs(link.rtt_ms - old.rtt_ms) >= max(1.0, 0.25 * old.rtt_ms):
            return True
        if abs(link.loss - old.loss) >= 0.05 or abs(link.jitter_ms - old.jitter_ms) >= max(
            1.0, 0.5 * old.jitter_ms
        ):
            return True
    return False


def _instances_moved(last: RobotRecord, new: RobotRecord) -> bool:
    if [(i.name, i.component, i.state, i.role) for i in last.instances] != [
        (i.name, i.component, i.state, i.role) for i in new.instances
    ]:
        return True
    band = max(16 << 20, new.metrics.mem_total // 100)
    return any(
        abs(a.cpu_pct - b.cpu_pct) >= 5.0 or abs(a.rss - b.rss) >= band
        for a, b in zip(last.instances, new.instances, strict=True)
    )


def _moved(old: float | None, new: float | None, band: float) -> bool:
    if old is None or new is None:
        return old is not new
    return abs(new - old) >= band
