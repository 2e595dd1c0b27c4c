"""The plain rclpy processes of tools/bench_ros2.py: a PoseStamped publisher and a subscriber.

Usage: python tools/bench_ros2_peers.py pub --topic /t --seconds 5 [--rate 0] [--size 100]
       python tools/bench_ros2_peers.py sub --topic /t --out counts.jsonl [--seconds 30]

How it works: both use QoS reliable, keep last `--depth` (100), volatile. The publisher waits (at
most 20 s) until a subscription matches, then publishes one `geometry_msgs/PoseStamped`, its
`header.frame_id` padded so that the serialized message is at least `--size` bytes, as fast as it
can (`--rate 0`) or at `--rate` Hz, for `--seconds`, each stamped with the wall clock, and prints
`{"sent", "first", "last", "bytes"}` (wall times) as JSON. The subscriber spins an
`rclpy.experimental.EventsExecutor` and appends a line like components/pose_sink.py's every
quarter second of input (`{"t", "n", "lat"}`); it ends `--idle` s after the last message
(once one came) or after `--seconds`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.experimental import EventsExecutor  # type: ignore[attr-defined]
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message

FLUSH_S = 0.25


def qos(depth: int) -> Any:
    """Reliable, keep last `depth`, volatile: the bench's QoS on both sides."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


def padded_pose(size: int) -> tuple[Any, int]:
    """A PoseStamped whose serialized form is at least `size` bytes, and that length."""

    msg = PoseStamped()
    msg.pose.orientation.w = 1.0
    for pad in range(0, max(size, 1) + 1):  # bounded: each byte of pad adds at least one
        msg.header.frame_id = "f" * pad
        length = len(serialize_message(msg))
        if length >= size:
            break
    return msg, length


def publish(args: argparse.Namespace) -> int:

    rclpy.init()
    node = Node("bench_pub")
    pub = node.create_publisher(PoseStamped, args.topic, qos(args.depth))
    msg, length = padded_pose(args.size)
    deadline = time.monotonic() + 20.0
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    if pub.get_subscription_count() < 1:
        print(json.dumps({"error": f"no subscription on {args.topic} within 20 s"}))
        return 1
    stamp = msg.header.stamp
    period = 1.0 / args.rate if args.rate > 0 else 0.0
    sent = 0
    first = time.time()
    start = time.monotonic()
    end = start + args.seconds
    while True:
        now = time.monotonic()
        if now >= end:
            break
        if period:
            due = start + sent * period
            if due > now:
                time.sleep(due - now)
        ns = time.time_ns()
        stamp.sec, stamp.nanosec = divmod(ns, 1_000_000_000)
        pub.publish(msg)
        sent += 1
    last = time.time()
    print(json.dumps({"sent": sent, "first": first, "last": last, "bytes": length}))
    node.destroy_node()
    rclpy.shutdown()
    return 0


def subscribe(args: argparse.Namespace) -> int:

    rclpy.init()
    node = Node("bench_sub")
    state: dict[str, Any] = {"n": 0, "lat": [], "flushed": time.time(), "heard": 0.0}
    out = open(args.out, "a", encoding="utf-8")  # noqa: SIM115 - closed below

    def flush(now: float) -> None:
        out.write(json.dumps({"t": now, "n": state["n"], "lat": state["lat"]}) + "\n")
        out.flush()
        state["lat"] = []
        state["flushed"] = now

    def heard(msg: Any) -> None:
        now = time.time()
        stamp = msg.header.stamp
        state["n"] += 1
        state["lat"].append(round((now - stamp.sec - stamp.nanosec * 1e-9) * 1e3, 4))
        state["heard"] = now
        if now - state["flushed"] >= FLUSH_S:
            flush(now)

    node.create_subscription(PoseStamped, args.topic, heard, qos(args.depth))
    executor = EventsExecutor()
    executor.add_node(node)
    print("ready", flush=True)
    deadline = time.monotonic() + args.seconds
    while time.monotonic() < deadline:  # bounded by --seconds; spins in slices of 0.2 s
        executor.spin_once(timeout_sec=0.2)
        if state["heard"] and time.time() - state["heard"] > args.idle:
            break
    flush(time.time())
    out.close()
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = p.add_subparsers(dest="role", required=True)
    pub = sub.add_parser("pub")
    pub.add_argument("--topic", required=True)
    pub.add_argument("--seconds", type=float, default=5.0)
    pub.add_argument("--rate", type=float, default=0.0, help="Hz; 0: as fast as it can")
    pub.add_argument("--size", type=int, default=100, help="serialized bytes, at least")
    pub.add_argument("--depth", type=int, default=100)
    s = sub.add_parser("sub")
    s.add_argument("--topic", required=True)
    s.add_argument("--out", required=True)
    s.add_argument("--seconds", type=float, default=60.0)
    s.add_argument("--idle", type=float, default=1.0)
    s.add_argument("--depth", type=int, default=100)
    args = p.parse_args(argv)
    return publish(args) if args.role == "pub" else subscribe(args)


if __name__ == "__main__":
    sys.exit(main())
