"""The ROS 2 support against issue 25's targets: bridge throughput and latency, a ROS 2 node's
failover and planned moves, and a ROS 2-format recording of a bridged system.

Usage: python tools/bench_ros2.py [--phases throughput,latency,failover,move,record]
                                  [--rounds 3] [--seconds 5] [--json out.json] [--keep DIR]
                                  (--help: every setting)

How it works (every process real, on loopback; DDS in the domain `--domain`, default
$ROS_DOMAIN_ID else 90, discovery kept on the machine):
- throughput: a plain rclpy publisher (tools/bench_ros2_peers.py) sends PoseStamped padded to
  `--size` serialized bytes as fast as it can for `--seconds`, QoS reliable / keep last
  `--depth` / volatile, to (a) a plain rclpy subscriber process on an EventsExecutor, and (b) a
  one-robot lab's system `{from: {ros2: /bench_bridge}, to: Sink.pose, policy: {buffer: D}}`:
  the `FromRosPose` bridge (its own host, an EventsExecutor; QoS reliable, keep last D, from
  the policy) writing to components.pose_sink:PoseSink over an ordinary sdrpeer connection
  (push all, buffer D, overwrite when full). Each counts what it takes (JSON lines every 0.25 s);
  the rate is taken over the publisher's run, its first 0.5 s left out. `--rounds` times, (a)
  and (b) alternating, each with a new publisher; medians and bridge / direct.
- latency: the same two paths, the publisher at `--latency-rate` Hz for `--latency-seconds`,
  each message stamped with the wall clock; each receiver takes now - stamp per message; added =
  p50(bridge) - p50(direct) (p90, p99 too), per round, median over rounds.
- failover: `--failovers` times a fresh 3-robot lab (preset lan) deploys examples/ros2/system.yaml
  and a ROS 2 probe in this process listens to /pose; once every component and its standbys are
  up and poses flow, the agent of the robot running `Odometry` is SIGKILLed. Measured: kill ->
  `Odometry` ACTIVE on another robot (the first `instance.state` active event of a survivor's
  /v1/events) and kill -> the first pose from the new pipeline at the probe (a /pose publisher
  it had not heard before the kill, or a pose stamped after the kill by a node it had).
- move, record: one 3-robot lab with the same system and a probe on /odom and /pose. record:
  `sdrpeer port record --format ros2` (sdrpeer.cli.port.record) of `ros2-odom-sub.out` (what
  `OdomToPose.odom` takes: an in-port cannot be tapped) and `OdomToPose.pose` for
  `--record-seconds`, every message then decoded by rclpy's `deserialize_message` with the
  class its schema names. move: `--moves` planned moves of
  `Odometry` (POST /v1/move, what `sdrpeer move Odometry --to R` does) to the robot of its
  standby; per move, on /odom: each node life is one publisher GID (the new node restarts its
  count at 0; the count is position.x * rate / speed), lost = count gaps within a life, dup =
  a count taken twice in a life, silent = first message of the new life - last of the old at the
  probe, by clock = the frames a 50 Hz source would have sent in that silence, new_first = the
  new life's first count heard (frames the new node sent before the probe matched it); on /pose:
  the /odom frames the probe heard that never came out as poses (matched by header.stamp).
"""

from __future__ import annotations

import argparse
import bisect
import itertools
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sdrpeer.client import AgentClient, post_when_elected, wait_for  # noqa: E402
from sdrpeer.errors import ApiError  # noqa: E402
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab  # noqa: E402
from sdrpeer.ros2.env import process_env  # noqa: E402
from sdrpeer.system.loader import load_system, parse_system  # noqa: E402
from tests.ros2_probe import Probe  # noqa: E402 - loads rclpy: after the bootstrap

PHASES = ("throughput", "latency", "failover", "move", "record")
PEERS = ROOT / "tools" / "bench_ros2_peers.py"
SYSTEM = ROOT / "examples" / "ros2" / "system.yaml"
ODOM_RATE = 50.0  # examples/ros2/system.yaml's rate_hz; the publisher's speed is 1 m/s
WARM_S = 0.5
LATE_S = 2.0
"""A receiver's lines up to this long after the publisher's last message count for its run."""
STAMP_SLACK_NS = 2_000
"""A pose is made of an /odom frame when their stamps agree to this: sdrpeer's typed values keep
a stamp as float seconds (~0.24 us apart at today's unix time), so nanoseconds do not survive."""
RECORDED = ("ros2-odom-sub.out", "OdomToPose.pose")
"""What the record phase taps: the frames OdomToPose.odom takes (an in-port cannot be tapped: the
out-port of the bridge that feeds it) and OdomToPose's output."""
TARGETS = {
    "throughput": "bridge >= 0.8x direct",
    "latency": "added p50 <= 0.5 ms",
    "failover": "Odometry ACTIVE elsewhere within the robot-death targets (hot standby: "
    "0.91-0.96 s in tools/bench_recovery.py); the subscriber receiving again",
    "move": "frames lost reported",
    "record": "every message decodes with rclpy",
}


def median(values: list[float]) -> float:
    return round(statistics.median(values), 4) if values else float("nan")


def pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return round(ordered[min(len(ordered) - 1, int(q / 100 * len(ordered)))], 4)


# ---- the lab --------------------------------------------------------------------------------


def clients_of(lab: RunningLab) -> dict[str, AgentClient]:
    return {r.name: AgentClient(str(r.api), r.token, timeout=5) for r in lab.lab.robots}


def status_of(clients: dict[str, AgentClient]) -> dict[str, Any]:
    """The status as the first robot that answers gives it."""
    for c in clients.values():
        try:
            return dict(c.get("/v1/status"))
        except (ApiError, OSError):
            continue
    raise ApiError("no agent answers")


def row(status: dict[str, Any], component: str) -> dict[str, Any]:
    return next((c for c in status.get("components", []) if c["component"] == component), {})


def settled(status: dict[str, Any]) -> bool:
    """Every component active, every wanted standby up and inactive."""
    rows = status.get("components", [])
    return bool(rows) and all(
        r.get("state") == "active"
        and len([s for s in r.get("standbys", []) if s.get("state") == "inactive"])
        >= r.get("standbys_wanted", 0)
        for r in rows
    )


def deploy(clients: dict[str, AgentClient], system_json: dict[str, Any], within: float) -> float:
    """Deploy and wait until settled; seconds it took."""
    t0 = time.monotonic()
    first = next(iter(clients.values()))
    post_when_elected(first, "/v1/deploy", {"system": system_json}, within)
    wait_for(lambda: status_of(clients), settled, "the system settled", within)
    return time.monotonic() - t0


def lab_env(domain: int) -> None:
    """This process and everything it starts: the bench's DDS domain, discovery on the machine."""
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"


@contextmanager
def running_lab(robots: int, where: Path) -> Iterator[RunningLab]:
    lab = start_lab(
        UpOptions(robots, where, preset="lan", timeout=60, allow_launchers=("ros2",)),
        say=lambda _: None,
    )
    try:
        yield lab
    finally:
        lab.stop(grace=3)


# ---- throughput and latency ----------------------------------------------------------------


def peer(*args: str) -> list[str]:
    return [sys.executable, str(PEERS), *args]


def publish(topic: str, seconds: float, rate: float, args: argparse.Namespace) -> dict[str, Any]:
    """Run the publisher to its end; what it printed."""
    cmd = peer("pub", "--topic", topic, "--seconds", str(seconds), "--rate", str(rate))
    cmd += ["--size", str(args.size), "--depth", str(args.depth)]
    done = subprocess.run(
        cmd,
        env=process_env(os.environ),
        capture_output=True,
        text=True,
        timeout=seconds + 60,
        check=False,
    )
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    result: dict[str, Any] = json.loads(lines[-1]) if lines else {"error": done.stderr[-2000:]}
    if "error" in result:
        raise RuntimeError(f"publisher on {topic}: {result['error']}")
    return result


def counted(path: Path, pub: dict[str, Any]) -> dict[str, Any]:
    """A receiver's lines over the publisher's run: rate after the warm-up, latencies."""
    lines = [json.loads(ln) for ln in path.read_text().splitlines() if ln.strip()]
    start, end = pub["first"] + WARM_S, pub["last"]
    inside = [ln for ln in lines if start <= ln["t"] <= end]
    rate = 0.0
    if len(inside) >= 2 and inside[-1]["t"] > inside[0]["t"]:
        rate = (inside[-1]["n"] - inside[0]["n"]) / (inside[-1]["t"] - inside[0]["t"])
    during = [ln for ln in lines if pub["first"] <= ln["t"] <= pub["last"] + LATE_S]
    lat = [x for ln in during for x in ln["lat"]]
    return {"per_s": round(rate, 1), "lat": lat}


def direct_run(
    topic: str, out: Path, seconds: float, rate: float, args: argparse.Namespace
) -> tuple[dict[str, Any], dict[str, Any]]:
    """A subscriber process and a publisher: what the subscriber took."""
    out.unlink(missing_ok=True)
    sub = subprocess.Popen(
        peer("sub", "--topic", topic, "--out", str(out), "--seconds", str(seconds + 60)),
        env=process_env(os.environ),
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert sub.stdout is not None
        ready = sub.stdout.readline()  # the subscriber's first line; it ends within its --seconds
        if not ready.startswith("ready"):
            raise RuntimeError(f"the subscriber did not start: {ready!r}")
        pub = publish(topic, seconds, rate, args)
        sub.wait(timeout=30)  # it ends 1 s after the last message
    finally:
        if sub.poll() is None:
            sub.kill()
            sub.wait(5)
    return pub, counted(out, pub)


def bridge_system(topic: str, sink_out: Path, depth: int) -> dict[str, Any]:
    text = f"""
version: 1
name: ros2-bench
components:
  - name: Sink
    target: components.pose_sink:PoseSink
    params: {{out: {json.dumps(str(sink_out))}}}
connections:
  - {{from: {{ros2: {topic}}}, to: Sink.pose, policy: {{buffer: {depth}}}}}
"""
    return parse_system(text, "ros2-bench.yaml").to_json()


def bridge_bench(args: argparse.Namespace, tmp: Path, which: list[str]) -> dict[str, Any]:
    """The throughput and latency phases on one 1-robot lab."""
    sink_out = tmp / "sink.jsonl"
    out: dict[str, Any] = {}
    with running_lab(1, tmp / "lab-bridge") as lab:
        clients = clients_of(lab)
        deploy(clients, bridge_system("/bench_bridge", sink_out, args.depth), 60)
        if "throughput" in which:
            rounds = []
            for i in range(args.rounds):
                pub_d, direct = direct_run(
                    f"/bench_direct_{i}", tmp / f"direct-t{i}.jsonl", args.seconds, 0.0, args
                )
                drained(sink_out)
                pub_b = publish("/bench_bridge", args.seconds, 0.0, args)
                bridge = counted_after(sink_out, pub_b)
                state = bridge_state(clients)
                rounds.append(
                    {
                        "direct_per_s": direct["per_s"],
                        "bridge_per_s": bridge["per_s"],
                        "sent_per_s_direct": round(pub_d["sent"] / args.seconds, 1),
                        "sent_per_s_bridge": round(pub_b["sent"] / args.seconds, 1),
                        "bytes": pub_b["bytes"],
                        "bridge_state": state,
                    }
                )
                say(f"  throughput round {i + 1}: {rounds[-1]}")
            d = median([r["direct_per_s"] for r in rounds])
            b = median([r["bridge_per_s"] for r in rounds])
            out["throughput"] = {
                "rounds": rounds,
                "direct_per_s": d,
                "bridge_per_s": b,
                "ratio": round(b / d, 3) if d else 0.0,
                "message_bytes": rounds[0]["bytes"],
                "seconds": args.seconds,
                "qos": f"reliable, keep last {args.depth}, volatile",
                "target": TARGETS["throughput"],
            }
        if "latency" in which:
            rounds = []
            for i in range(args.rounds):
                _, direct = direct_run(
                    f"/bench_direct_l{i}",
                    tmp / f"direct-l{i}.jsonl",
                    args.latency_seconds,
                    args.latency_rate,
                    args,
                )
                drained(sink_out)
                pub_b = publish("/bench_bridge", args.latency_seconds, args.latency_rate, args)
                bridge = counted_after(sink_out, pub_b)
                r: dict[str, Any] = {
                    "direct_n": len(direct["lat"]),
                    "bridge_n": len(bridge["lat"]),
                    "bridge_state": bridge_state(clients),
                }
                for q in (50, 90, 99):
                    r[f"direct_p{q}_ms"] = pct(direct["lat"], q)
                    r[f"bridge_p{q}_ms"] = pct(bridge["lat"], q)
                    r[f"added_p{q}_ms"] = round(r[f"bridge_p{q}_ms"] - r[f"direct_p{q}_ms"], 4)
                rounds.append(r)
                say(f"  latency round {i + 1}: {r}")
            out["latency"] = {
                "rounds": rounds,
                "rate_hz": args.latency_rate,
                "seconds": args.latency_seconds,
                **{
                    f"{k}_p{q}_ms": median([r[f"{k}_p{q}_ms"] for r in rounds])
                    for k in ("direct", "bridge", "added")
                    for q in (50, 90, 99)
                },
                "target": TARGETS["latency"],
            }
    return out


def bridge_state(clients: dict[str, AgentClient]) -> str:
    """The bridge's state now, and its last error if it has one (a flood may put it in ERROR)."""
    rows = next(iter(clients.values())).get("/v1/instances")
    bridge: dict[str, Any] = next((i for i in rows if i["name"].startswith("ros2-")), {})
    error = bridge.get("last_error")
    return str(bridge.get("state")) + (f" ({error})" if error else "")


def drained(sink_out: Path, quiet: float = 1.0, within: float = 60.0) -> None:
    """Wait (at most `within` s) until the sink has written nothing for `quiet` s: what an
    earlier run left queued in the bridge has been taken."""
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        if not sink_out.exists() or time.time() - sink_out.stat().st_mtime >= quiet:
            return
        time.sleep(0.1)
    raise RuntimeError(f"the sink still takes frames {within:g} s on")


def counted_after(sink_out: Path, pub: dict[str, Any]) -> dict[str, Any]:
    """The sink's lines over a publisher's run, once it has taken what was queued."""
    drained(sink_out)
    return counted(sink_out, pub)


# ---- the probe -----------------------------------------------------------------------------


def stamp_of(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def until(what: str, probe: Callable[[], Any], ok: Callable[[Any], bool], within: float) -> Any:
    return wait_for(probe, ok, what, within)


# ---- failover ------------------------------------------------------------------------------


def failover_round(i: int, tmp: Path, system_json: dict[str, Any]) -> dict[str, Any]:
    from geometry_msgs.msg import PoseStamped  # noqa: PLC0415 - ROS 2 wheels

    probe = Probe()
    try:
        probe.listen("/pose", PoseStamped)
        with running_lab(3, tmp / f"lab-failover-{i}") as lab:
            clients = clients_of(lab)
            deploy(clients, system_json, 90)
            until("poses at the probe", lambda: probe.heard("/pose"), lambda m: len(m) >= 50, 60)
            victim = row(status_of(clients), "Odometry")["robot"]
            survivors = {n: c for n, c in clients.items() if n != victim}
            last_id = {n: max([e["id"] for e in c.events()] or [0]) for n, c in survivors.items()}
            pid = next(r.pid for r in lab.lab.robots if r.name == victim)
            assert pid is not None
            before = {gid for _, gid, _ in probe.heard("/pose")}
            os.kill(pid, signal.SIGKILL)
            killed = time.time()
            kill_ns = int(killed * 1e9)

            def active_at() -> float | None:
                for n, c in survivors.items():
                    try:
                        events = c.events(since=last_id[n])
                    except (ApiError, OSError):
                        continue
                    hits = [
                        e["ts"]
                        for e in events
                        if e["kind"] == "instance.state"
                        and e["detail"].get("component") == "Odometry"
                        and e["detail"].get("state") == "active"
                        and e["robot"] != victim
                        and e["ts"] > killed
                    ]
                    if hits:
                        return float(min(hits))
                return None

            def fresh() -> list[tuple[float, bytes, Any]]:
                return [
                    m
                    for m in probe.heard("/pose", since=killed)
                    if m[1] not in before or stamp_of(m[2]) > kill_ns
                ]

            active = until("Odometry ACTIVE on a survivor", active_at, lambda t: t is not None, 60)
            first = until("fresh poses", fresh, lambda m: len(m) >= 1, 60)[0]
            old_after = [m for m in probe.heard("/pose", since=killed + 0.5) if m[1] in before]
            dead = [
                e
                for c in survivors.values()
                for e in c.events(since=0)
                if e["ts"] > killed and "dead" in e["kind"]
            ]
            moved_to = row(status_of(survivors), "Odometry").get("robot")
            r = {
                "victim": victim,
                "to": moved_to,
                "active_s": round(active - killed, 3),
                "fresh_pose_s": round(first[0] - killed, 3),
                "declared_dead_s": round(min(e["ts"] for e in dead) - killed, 3) if dead else None,
                "old_publisher_heard_after_kill": len(old_after),
            }
    finally:
        probe.close()
    return r


def failover(args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    system_json = load_system(SYSTEM).to_json()
    rounds = []
    for i in range(args.failovers):
        rounds.append(failover_round(i, tmp, system_json))
        say(f"  failover round {i + 1}: {rounds[-1]}")
    return {
        "rounds": rounds,
        "active_s": median([r["active_s"] for r in rounds]),
        "fresh_pose_s": median([r["fresh_pose_s"] for r in rounds]),
        "declared_dead_s": median([r["declared_dead_s"] for r in rounds if r["declared_dead_s"]]),
        "target": TARGETS["failover"],
    }


# ---- moves and recording -------------------------------------------------------------------


def near(ordered: list[int], stamp: int, within_ns: int = STAMP_SLACK_NS) -> bool:
    """Whether `ordered` (sorted ns) holds a stamp within `within_ns` of `stamp`."""
    i = bisect.bisect_left(ordered, stamp - within_ns)
    return i < len(ordered) and ordered[i] <= stamp + within_ns


def odom_count(msg: Any) -> int:
    """The Odometry publisher's own count (components/ros2/odometry.py: x = n * speed / rate)."""
    return round(float(msg.pose.pose.position.x) * ODOM_RATE)


def lives(messages: list[tuple[float, bytes, int]]) -> dict[bytes, list[tuple[float, int]]]:
    """(arrival, count) per publisher GID, in arrival order."""
    out: dict[bytes, list[tuple[float, int]]] = {}
    for t, gid, n in messages:
        out.setdefault(gid, []).append((t, n))
    return out


def continuity(counts: list[int]) -> tuple[int, int]:
    """(lost: counts skipped, dup: counts not above the last one) in one life."""
    lost = dup = 0
    for a, b in itertools.pairwise(counts):
        if b > a + 1:
            lost += b - a - 1
        elif b <= a:
            dup += 1
    return lost, dup


def move_once(clients: dict[str, AgentClient], probe: Probe, t_from: float) -> dict[str, Any]:
    status = status_of(clients)
    odo = row(status, "Odometry")
    origin = odo["robot"]
    to = next((s["robot"] for s in odo.get("standbys", [])), None) or next(
        n for n in clients if n != origin
    )
    old = {gid for _, gid, _ in probe.heard("/odom", since=time.time() - 1.0)}
    t0 = time.time()
    post_when_elected(clients[origin], "/v1/move", {"component": "Odometry", "to": to}, 30)
    until(
        f"Odometry ACTIVE on {to}",
        lambda: row(status_of(clients), "Odometry"),
        lambda r: r.get("robot") == to and r.get("state") == "active",
        60,
    )
    done_s = time.time() - t0

    def new_msgs() -> list[Any]:
        return [m for m in probe.heard("/odom", since=t0) if m[1] not in old]

    until("/odom from the new node for 1 s", new_msgs, lambda m: m and m[-1][0] - m[0][0] >= 1, 30)
    until("the system settled", lambda: status_of(clients), settled, 90)
    t1 = time.time()
    odom = [(t, gid, odom_count(m)) for t, gid, m in probe.heard("/odom", since=t_from)]
    by_life = lives([m for m in odom if m[0] <= t1])
    old_lives = [g for g in by_life if g in old]
    new_lives = [g for g in by_life if g not in old]
    lost = dup = 0
    for msgs in by_life.values():
        a, b = continuity([n for _, n in msgs])
        lost, dup = lost + a, dup + b
    last_old = max((by_life[g][-1][0] for g in old_lives), default=t0)
    first_new = min((by_life[g][0][0] for g in new_lives), default=t1)
    silent = first_new - last_old
    # the poses that should have come of the /odom frames the probe heard (by header.stamp)
    heard = [
        (gid, stamp_of(m)) for t, gid, m in probe.heard("/odom", since=t_from) if t <= t1 - 0.5
    ]
    poses = [stamp_of(m) for t, _, m in probe.heard("/pose", since=t_from) if t <= t1]
    pose_stamps = set(poses)
    made = sorted(poses)
    missing = [(g, st) for g, st in heard if not near(made, st)]
    return {
        "from": origin,
        "to": to,
        "move_s": round(done_s, 3),
        "odom_lost_in_life": lost,
        "odom_dup_in_life": dup,
        "odom_lives": len(by_life),
        "silent_s": round(silent, 3),
        "silent_frames_by_clock": max(0, round(silent * ODOM_RATE) - 1),
        "overlap_old_after_new": sum(1 for g in old_lives for t, _ in by_life[g] if t > first_new),
        "new_first_count": min((by_life[g][0][1] for g in new_lives), default=-1),
        "pose_missing_of_odom_heard": len(missing),
        "pose_missing_old_life": sum(1 for g, _ in missing if g in old),
        "pose_missing_new_life": sum(1 for g, _ in missing if g not in old),
        "pose_dup": len(poses) - len(pose_stamps),
        "pose_heard": len(poses),
    }


def decode_recording(path: Path) -> dict[str, Any]:
    from mcap.reader import make_reader  # noqa: PLC0415
    from rclpy.serialization import deserialize_message  # noqa: PLC0415

    from sdrpeer.ros2.bridge import import_ros_type  # noqa: PLC0415

    per: dict[str, dict[str, int]] = {}
    failures: list[str] = []
    with path.open("rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            counts = per.setdefault(channel.topic, {"decoded": 0, "failed": 0})
            try:
                name = schema.name if schema is not None else "?"
                deserialize_message(message.data, import_ros_type(name))
            except Exception as exc:  # counted: the figure is how many decode
                counts["failed"] += 1
                if len(failures) < 5:
                    failures.append(f"{channel.topic}: {exc}")
                continue
            counts["decoded"] += 1
    return {"per_channel": per, "failures": failures}


def system_bench(args: argparse.Namespace, tmp: Path, which: list[str]) -> dict[str, Any]:
    from geometry_msgs.msg import PoseStamped  # noqa: PLC0415
    from nav_msgs.msg import Odometry  # noqa: PLC0415

    from sdrpeer.cli.port import RECORD_POLICY, record  # noqa: PLC0415

    out: dict[str, Any] = {}
    probe = Probe()
    try:
        probe.listen("/odom", Odometry)
        probe.listen("/pose", PoseStamped)
        with running_lab(3, tmp / "lab-system") as lab:
            clients = clients_of(lab)
            deploy(clients, load_system(SYSTEM).to_json(), 90)
            until("poses at the probe", lambda: probe.heard("/pose"), lambda m: len(m) >= 50, 60)
            if "record" in which:
                path = tmp / "bridged.mcap"
                body = {"duration": args.record_seconds, "policy": RECORD_POLICY}
                first = next(iter(clients.values()))
                done = record(first, list(RECORDED), path, body, "ros2")
                dec = decode_recording(path)
                decoded = sum(c["decoded"] for c in dec["per_channel"].values())
                failed = sum(c["failed"] for c in dec["per_channel"].values())
                out["record"] = {
                    "seconds": args.record_seconds,
                    "recorded": done["frames"],
                    "decoded": decoded,
                    "failed": failed,
                    **dec,
                    "tap_dropped": int(done["end"].get("dropped", 0)),
                    "file_kb": round(path.stat().st_size / 1e3, 1),
                    "target": TARGETS["record"],
                }
                say(f"  record: {out['record']}")
            if "move" in which:
                rounds = []
                for i in range(args.moves):
                    t_from = time.time() - 1.0
                    rounds.append(move_once(clients, probe, t_from))
                    say(f"  move {i + 1}: {rounds[-1]}")
                keys = [k for k in rounds[0] if isinstance(rounds[0][k], (int, float))]
                out["move"] = {
                    "rounds": rounds,
                    **{k: median([float(r[k]) for r in rounds]) for k in keys},
                    "totals": {
                        k: sum(r[k] for r in rounds)
                        for k in (
                            "odom_lost_in_life",
                            "odom_dup_in_life",
                            "pose_missing_of_odom_heard",
                            "pose_missing_old_life",
                            "pose_missing_new_life",
                        )
                    },
                    "target": TARGETS["move"],
                }
    finally:
        probe.close()
    return out


# ---- the command ---------------------------------------------------------------------------


def say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def table(title: str, rows: list[tuple[str, Any]]) -> None:
    print(f"\n{title}")
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"  {k:<{width}}  {v}")


def report(r: dict[str, Any]) -> None:
    if "throughput" in r:
        t = r["throughput"]
        table(
            f"throughput: PoseStamped {t['message_bytes']} B, {t['qos']}, {t['seconds']:g} s x "
            f"{len(t['rounds'])} rounds (medians)",
            [
                ("rclpy pub -> rclpy sub (EventsExecutor)", f"{t['direct_per_s']:,.0f} msg/s"),
                ("rclpy pub -> FromRosPose -> sdrpeer sink", f"{t['bridge_per_s']:,.0f} msg/s"),
                ("ratio", f"{t['ratio']:.2f}   target: {t['target']}"),
                ("bridge after each round", "; ".join(r["bridge_state"] for r in t["rounds"])),
            ],
        )
    if "latency" in r:
        lt = r["latency"]
        table(
            f"latency: {lt['rate_hz']:g} Hz for {lt['seconds']:g} s x {len(lt['rounds'])} rounds "
            "(medians, ms)",
            [
                (k, " ".join(f"p{q} {lt[f'{k}_p{q}_ms']:.3f}" for q in (50, 90, 99)))
                for k in ("direct", "bridge", "added")
            ]
            + [("target", lt["target"])],
        )
    if "failover" in r:
        f = r["failover"]
        table(
            f"failover: SIGKILL of the agent running Odometry, {len(f['rounds'])} rounds (medians)",
            [
                ("kill -> declared dead", f"{f['declared_dead_s']} s"),
                ("kill -> Odometry ACTIVE on a survivor", f"{f['active_s']} s"),
                ("kill -> first fresh /pose at the probe", f"{f['fresh_pose_s']} s"),
                ("target", f["target"]),
            ],
        )
    if "move" in r:
        m = r["move"]
        table(
            f"move: planned moves of Odometry, {len(m['rounds'])} moves (medians; totals)",
            [
                ("move request -> ACTIVE on the new robot", f"{m['move_s']} s"),
                ("/odom silent at the probe", f"{m['silent_s']} s"),
                ("  frames a 50 Hz source sends in it", f"{m['silent_frames_by_clock']}"),
                ("/odom count lost within a node life", f"{m['totals']['odom_lost_in_life']}"),
                ("/odom taken twice within a life", f"{m['totals']['odom_dup_in_life']}"),
                ("new node's first count heard", f"{m['new_first_count']}"),
                (
                    "/odom heard, no pose made of it (old node; new node)",
                    f"{m['totals']['pose_missing_of_odom_heard']} "
                    f"({m['totals']['pose_missing_old_life']}; "
                    f"{m['totals']['pose_missing_new_life']})",
                ),
                ("target", m["target"]),
            ],
        )
    if "record" in r:
        rc = r["record"]
        table(
            f"record: {' + '.join(RECORDED)}, --format ros2, {rc['seconds']:g} s",
            [
                ("messages recorded", rc["recorded"]),
                ("decoded by rclpy", f"{rc['decoded']} (failed {rc['failed']})"),
                ("per channel", json.dumps(rc["per_channel"])),
                ("tap dropped", rc["tap_dropped"]),
                ("target", rc["target"]),
            ],
        )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument(
        "--phases", default=",".join(PHASES), help="comma-separated, of " + ", ".join(PHASES)
    )
    p.add_argument("--rounds", type=int, default=3, help="throughput and latency rounds")
    p.add_argument("--seconds", type=float, default=5.0, help="throughput: each run")
    p.add_argument("--size", type=int, default=100, help="serialized PoseStamped bytes")
    p.add_argument("--depth", type=int, default=100, help="QoS keep last N (reliable)")
    p.add_argument("--latency-rate", type=float, default=200.0)
    p.add_argument("--latency-seconds", type=float, default=10.0)
    p.add_argument("--failovers", type=int, default=3)
    p.add_argument("--moves", type=int, default=3)
    p.add_argument("--record-seconds", type=float, default=30.0)
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "90")))
    p.add_argument("--keep", type=Path, metavar="DIR", help="keep the labs and files in DIR")
    p.add_argument("--json", type=Path, help="also write the figures to this file")
    args = p.parse_args(argv)
    which = [w.strip() for w in args.phases.split(",") if w.strip()]
    unknown = [w for w in which if w not in PHASES]
    if unknown:
        p.error(f"unknown phase(s) {', '.join(unknown)}; expected {', '.join(PHASES)}")
    lab_env(args.domain)
    r: dict[str, Any] = {
        "domain": args.domain,
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    with tempfile.TemporaryDirectory() as scratch:
        tmp = args.keep or Path(scratch)
        tmp.mkdir(parents=True, exist_ok=True)
        if {"throughput", "latency"} & set(which):
            r.update(bridge_bench(args, tmp, which))
        if "failover" in which:
            r["failover"] = failover(args, tmp)
        if {"move", "record"} & set(which):
            r.update(system_bench(args, tmp, which))
    report(r)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(r, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
