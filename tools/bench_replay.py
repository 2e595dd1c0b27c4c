#!/usr/bin/env python3
"""Gossip replayed to another robot (issue 30): how many captured datagrams are accepted.

Usage: python tools/bench_replay.py [--robots 3] [--datagrams 56] [--preset lan] [--no-stale]
       [--no-restart] [--json PATH]            (root: the capture is a raw socket on lo)

How it works: a lab of `--robots` real agents on loopback (`sdrpeer lab up`, one cluster key).
A raw socket on `lo` (sdrpeer.netlab.capture) records the first `--datagrams` gossip datagrams
on their way to robot-2, sent by the other robots. At once (their age is printed), an attacker
without the key sends them, from a fresh UDP socket, to every other robot and, as a control, to
robot-2 itself. Each robot's rejection counters (`GET /v1/agent` `rejected`, what `sdrpeer
agent-info` shows) and its membership core's `misdirected` and `self_loop` counters (datagrams
that got past the codec: a ping for another robot, a robot's own datagram back) are read before
and after, once the replays were counted (at most `--wait` seconds); a replay not refused was
accepted. The target: 0 accepted by any robot other than robot-2.

Then (unless `--no-stale`) the stale replay: once the captured datagrams are older than the
30 s freshness window plus 6 s, each is sent to robot-2 again from its own source port (as
from as many spoofed addresses), and the answers coming back within 2 s of the last are counted
(a robot answers a stale datagram newer than anything its sender sent before with an empty
gossip, so that a robot whose clock is behind catches up; a replay should get nothing).

Then (unless `--no-restart`) the restart: `--datagrams` more are captured on their way to
robot-2, robot-2 is killed (SIGKILL) and started again with the same data dir (its replay
windows are gone), and once it sees every robot alive the captured datagrams are sent to its new
life: accepted, and refused by reason, as above.

The table prints, per robot, the datagrams replayed, accepted and refused by reason; `--json`
writes the same figures.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import socket
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sdrpeer.client import AgentClient  # noqa: E402
from sdrpeer.errors import ApiError  # noqa: E402
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab  # noqa: E402
from sdrpeer.netlab.capture import Capture  # noqa: E402

FRESHNESS_S = 30.0
"""The codec's freshness window (sdrpeer.gossip.replay)."""
CORE_COUNTERS = ("misdirected", "self_loop")


def hostport(text: str | None) -> tuple[str, int]:
    """("127.0.0.1", 7946) from "127.0.0.1:7946"."""
    assert text is not None
    host, port = text.rsplit(":", 1)
    return host, int(port)


def counters(api: str) -> dict[str, Any]:
    """One agent's rejections by reason, its core's counters and its datagrams in."""
    info = AgentClient(api, timeout=5).agent()
    return {
        "rejected": dict(info["rejected"]),
        "core": {k: int(info["gossip"].get(k, 0)) for k in CORE_COUNTERS},
        "in": int(info["messages"]["in"]),
    }


def capture_to(port: int, count: int, within: float) -> tuple[list[bytes], float]:
    """The first `count` datagrams seen on their way to `port`, and when the first was seen."""
    with Capture([port]) as capture:
        deadline = time.monotonic() + within
        first = 0.0
        while time.monotonic() < deadline:
            seen = capture.to_port(port)
            if seen and not first:
                first = time.monotonic()
            if len(seen) >= count:
                return seen[:count], first
            time.sleep(0.05)
    raise RuntimeError(f"only {len(capture.to_port(port))} datagrams to port {port} in {within} s")


def replay(
    running: RunningLab, datagrams: list[bytes], wait: float, only: str = ""
) -> dict[str, Any]:
    """Send `datagrams` to every robot (or `only` that one); per robot, what its counters say
    of them."""
    robots = [r for r in running.lab.robots if not only or r.name == only]
    before = {r.name: counters(str(r.api)) for r in robots}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for robot in robots:
            for data in datagrams:
                sock.sendto(data, hostport(robot.gossip))
    out: dict[str, Any] = {}
    for robot in robots:
        was = before[robot.name]
        deadline = time.monotonic() + wait
        while True:  # until every replay is refused, or `wait` s (the rest were accepted)
            now = counters(str(robot.api))
            refused = {
                reason: n - was["rejected"].get(reason, 0)
                for reason, n in now["rejected"].items()
                if n > was["rejected"].get(reason, 0)
            }
            if sum(refused.values()) >= len(datagrams) or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        out[robot.name] = {
            "replayed": len(datagrams),
            "refused": refused,
            "accepted": max(0, len(datagrams) - sum(refused.values())),
            "core": {k: now["core"][k] - was["core"][k] for k in CORE_COUNTERS},
            "received": now["in"] - was["in"],
        }
    return out


def restart_replay(running: RunningLab, count: int, wait: float) -> dict[str, Any]:
    """Capture `count` datagrams to robot-2, kill it, start it again, replay them to it."""
    two = running.lab.robot("robot-2")
    proc = running.process("robot-2")
    assert two is not None
    assert proc is not None
    captured, first_seen = capture_to(hostport(two.gossip)[1], count, within=60.0)
    proc.kill()
    proc.wait(timeout=10)
    running.restart("robot-2")
    running.wait_started("robot-2", timeout=30)
    names = {r.name for r in running.lab.robots}
    deadline = time.monotonic() + 30
    while not names <= alive_at(str(two.api)):
        if time.monotonic() > deadline:
            raise RuntimeError("the restarted robot-2 does not see every robot alive in 30 s")
        time.sleep(0.1)
    age = round(time.monotonic() - first_seen, 2)
    out = replay(running, captured, wait, only="robot-2")["robot-2"]
    return {"age_s": age, **out}


def alive_at(api: str) -> set[str]:
    """The members `api`'s agent sees alive (none while it does not answer)."""
    try:
        members = AgentClient(api, timeout=2).members()
    except ApiError:
        return set()
    return {str(m["name"]) for m in members if m.get("state") == "alive"}


def stale_answers(target: tuple[str, int], datagrams: list[bytes]) -> dict[str, int]:
    """Send each datagram to `target` from its own socket; the answers within 2 s of the last."""
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in datagrams]
    answers = answer_bytes = 0
    try:
        for sock, data in zip(socks, datagrams, strict=True):
            sock.bind(("127.0.0.1", 0))
            sock.sendto(data, target)
        deadline = time.monotonic() + 2.0
        while (left := deadline - time.monotonic()) > 0:
            ready, _, _ = select.select(socks, [], [], left)
            for sock in ready:
                answer_bytes += len(sock.recv(65535))
                answers += 1
    finally:
        for sock in socks:
            sock.close()
    return {"sources": len(datagrams), "answers": answers, "answer_bytes": answer_bytes}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--robots", type=int, default=3, help="robots in the lab (at least 3)")
    p.add_argument("--datagrams", type=int, default=56, help="datagrams to robot-2 captured")
    p.add_argument("--preset", default="lan", help="the agents' preset (default lan)")
    p.add_argument("--wait", type=float, default=5.0, help="seconds to wait for the counts")
    p.add_argument("--no-stale", action="store_true", help="skip the stale replay (36 s)")
    p.add_argument("--no-restart", action="store_true", help="skip the replay to a restart")
    p.add_argument("--json", type=Path, metavar="PATH", help="write the figures here")
    args = p.parse_args(argv)
    if os.geteuid() != 0:
        p.error("the capture is a raw socket on lo: run as root")
    if args.robots < 3:
        p.error("--robots must be at least 3 (robot-2's senders, and a third robot to replay to)")
    doc: dict[str, Any] = {"robots": args.robots, "preset": args.preset}
    with tempfile.TemporaryDirectory(prefix="bench-replay-") as tmp:
        options = UpOptions(args.robots, Path(tmp) / "lab", preset=args.preset, timeout=60)
        running = start_lab(options, say=lambda _: None)
        try:
            two = running.lab.robot("robot-2")
            assert two is not None
            port = hostport(two.gossip)[1]
            captured, first_seen = capture_to(port, args.datagrams, within=60.0)
            doc["age_s"] = round(time.monotonic() - first_seen, 2)
            doc["replay"] = replay(running, captured, args.wait)
            if not args.no_stale:
                time.sleep(max(0.0, first_seen + FRESHNESS_S + 6 - time.monotonic()))
                doc["stale_age_s"] = round(time.monotonic() - first_seen, 1)
                doc["stale"] = stale_answers(hostport(two.gossip), captured)
            if not args.no_restart:
                doc["restart"] = restart_replay(running, args.datagrams, args.wait)
        finally:
            running.stop(grace=5)
    print(
        f"{args.datagrams} gossip datagrams captured on their way to robot-2 ({args.robots} "
        f"robots, preset {args.preset}), replayed to every robot {doc['age_s']} s after the "
        "first was captured:"
    )
    reasons = sorted({r for v in doc["replay"].values() for r in v["refused"]})
    head = f"{'robot':<10}{'replayed':>9}{'accepted':>9}" + "".join(f"{r:>16}" for r in reasons)
    print(head + "".join(f"{k:>13}" for k in CORE_COUNTERS))
    for name, v in doc["replay"].items():
        row = f"{name:<10}{v['replayed']:>9}{v['accepted']:>9}"
        row += "".join(f"{v['refused'].get(r, 0):>16}" for r in reasons)
        print(row + "".join(f"{v['core'][k]:>13}" for k in CORE_COUNTERS))
    others = sum(v["accepted"] for name, v in doc["replay"].items() if name != "robot-2")
    doc["accepted_by_other_robots"] = others
    print(f"accepted by robots other than robot-2: {others} (target 0)")
    if "stale" in doc:
        s = doc["stale"]
        print(
            f"stale replay to robot-2 ({doc['stale_age_s']} s old) from {s['sources']} source "
            f"ports: {s['answers']} answers, {s['answer_bytes']} bytes"
        )
    if "restart" in doc:
        r = doc["restart"]
        refused = ", ".join(f"{k} {v}" for k, v in sorted(r["refused"].items())) or "none"
        print(
            f"robot-2 killed and started again: {r['replayed']} datagrams captured on their way "
            f"to its previous life, replayed {r['age_s']} s after the first was captured: "
            f"{r['accepted']} accepted, refused: {refused}"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
    restart_accepted = doc.get("restart", {}).get("accepted", 0)
    return 0 if others == 0 and restart_accepted == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
