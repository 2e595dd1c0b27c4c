"""Frames lost over planned moves (and over crashes) of a receiving component, on real agents.

Usage: python tools/bench_moves.py [--moves 100] [--crashes 10] [--rate 200] [--standby]
                                   [--netns] [--json out.json]

How it works: a lab of three agents runs `components.ledger`: a `Sequencer` pinned to robot-1
publishes 1, 2, 3, ... at `--rate` Hz over a `fifo`/`block` connection to a `Ledger`, which
writes every number it takes to its own file. The Ledger is then moved `--moves` times between
robot-2 and robot-3 with `POST /v1/move` (what `sdrpeer move Ledger --to robot-K` does: a
planned move — the old instance is deactivated, hands over its state and stops; the new one
starts) and each move is timed until the Ledger is ACTIVE on its new robot as the status says.
With `--standby` the Ledger has a hot standby on the other robot, so a move promotes it. Then
its host is SIGKILLed `--crashes` times (the recovery ladder restarts it). Each phase ends with
the stream flowing again for a second; the ledger files then say which numbers were taken:
lost (a number below the highest taken that no instance took; target 0) and taken twice. The
Sequencer's port counters say how many frames were replayed to a new instance (frames the old
one never took: what a stream without acknowledgements loses).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from components.ledger import ledger_system, read_ledgers  # noqa: E402
from sdrpeer.client import (  # noqa: E402
    AgentClient,
    post_when_elected,
    wait_for,
)
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab  # noqa: E402
from sdrpeer.system.loader import parse_system  # noqa: E402


def ledger_row(client: AgentClient) -> dict[str, Any]:
    doc = client.get("/v1/status")
    return next((c for c in doc.get("components", []) if c["component"] == "Ledger"), {})


def instances(client: AgentClient) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = client.get("/v1/instances")
    return rows


def sequencer_ports(client: AgentClient) -> dict[str, Any]:
    row = next((r for r in instances(client) if r.get("component") == "Sequencer"), {})
    ports: dict[str, Any] = (row.get("ports") or {}).get("out", {})
    return ports


def move_once(client: AgentClient, to: str, timeout: float) -> float:
    t0 = time.monotonic()
    post_when_elected(client, "/v1/move", {"component": "Ledger", "to": to}, timeout)
    wait_for(
        lambda: ledger_row(client),
        lambda row: row.get("robot") == to and row.get("state") == "active",
        f"Ledger ACTIVE on {to}",
        timeout,
    )
    return time.monotonic() - t0


def flowing(ledger_dir: Path, seconds: float = 1.0) -> None:
    """Wait until the Ledger has taken numbers again for `seconds`."""
    start = read_ledgers(str(ledger_dir))["highest"]
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if read_ledgers(str(ledger_dir))["highest"] > start:
            time.sleep(seconds)
            return
        time.sleep(0.1)
    raise RuntimeError("the stream did not flow again within 30 s")


def kill_ledger_host(running: RunningLab, clients: dict[str, AgentClient]) -> str:
    for name, client in clients.items():
        for row in instances(client):
            if row.get("component") == "Ledger" and row.get("state") == "ACTIVE" and row.get("pid"):
                os.kill(int(row["pid"]), signal.SIGKILL)
                return name
    raise RuntimeError("no ACTIVE Ledger host to kill")


def phase(ledger_dir: Path, before: dict[str, Any]) -> dict[str, Any]:
    after = read_ledgers(str(ledger_dir))
    return {k: after[k] - before.get(k, 0) for k in ("taken", "lost", "duplicates")} | {
        "highest": after["highest"]
    }


def measure(args: argparse.Namespace) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as scratch:
        tmp = args.keep or Path(scratch)
        ledger_dir = Path(tmp) / "ledger"
        text = ledger_system(str(ledger_dir), args.rate, standby=args.standby)
        system = parse_system(text, "moves.yaml")
        running = start_lab(
            UpOptions(3, Path(tmp) / "lab", preset="lan", netns=args.netns, timeout=60),
            say=lambda _: None,
        )
        try:
            clients = {
                r.name: AgentClient(str(r.api), r.token, timeout=5) for r in running.lab.robots
            }
            first = clients["robot-1"]
            post_when_elected(first, "/v1/deploy", {"system": system.to_json()}, 30)
            wait_for(
                lambda: ledger_row(first), lambda r: r.get("state") == "active", "deployed", 60
            )
            flowing(ledger_dir)
            base = read_ledgers(str(ledger_dir))
            times: list[float] = []
            for i in range(args.moves):
                to = "robot-3" if ledger_row(first).get("robot") == "robot-2" else "robot-2"
                times.append(move_once(first, to, 30))
                time.sleep(args.gap)
                if (i + 1) % 10 == 0:
                    print(f"  {i + 1} moves, median {statistics.median(times):.2f} s", flush=True)
            flowing(ledger_dir)
            moves = phase(ledger_dir, base)
            replayed_moves = int(sequencer_ports(first).get("replayed", 0))
            base = read_ledgers(str(ledger_dir))
            recover: list[float] = []
            for _ in range(args.crashes):
                kill_ledger_host(running, clients)
                t0 = time.monotonic()
                time.sleep(0.2)
                wait_for(lambda: ledger_row(first), lambda r: r.get("state") == "active",
                         "Ledger ACTIVE again", 60)  # fmt: skip
                recover.append(time.monotonic() - t0)
                flowing(ledger_dir, 0.5)
            flowing(ledger_dir)
            crashes = phase(ledger_dir, base)
            replayed_all = int(sequencer_ports(first).get("replayed", 0))
        finally:
            running.stop(grace=3)
    return {
        "moves": args.moves,
        "rate_hz": args.rate,
        "standby": args.standby,
        "network": "namespaces" if args.netns else "loopback",
        "moves_frames_taken": moves["taken"],
        "moves_frames_lost": moves["lost"],
        "moves_frames_duplicated": moves["duplicates"],
        "moves_frames_replayed": replayed_moves,
        "move_time_s_median": round(statistics.median(times), 3) if times else None,
        "move_time_s_p95": round(sorted(times)[int(0.95 * (len(times) - 1))], 3) if times else None,
        "crashes": args.crashes,
        "crashes_frames_taken": crashes["taken"],
        "crashes_frames_lost": crashes["lost"],
        "crashes_frames_duplicated": crashes["duplicates"],
        "crashes_frames_replayed": replayed_all - replayed_moves,
        "crash_recovery_s_median": round(statistics.median(recover), 3) if recover else None,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--moves", type=int, default=100)
    p.add_argument("--crashes", type=int, default=10)
    p.add_argument("--rate", type=float, default=200.0, help="numbers per second")
    p.add_argument("--gap", type=float, default=0.3, help="seconds between moves")
    p.add_argument("--standby", action="store_true", help="the Ledger has a hot standby")
    p.add_argument("--netns", action="store_true", help="robots in network namespaces (root)")
    p.add_argument("--keep", type=Path, metavar="DIR", help="keep the lab and ledgers in DIR")
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    r = measure(args)
    rows = [
        ("planned moves", r["moves"], r["moves_frames_taken"], r["moves_frames_lost"],
         r["moves_frames_duplicated"], r["moves_frames_replayed"], r["move_time_s_median"]),
        ("host crashes", r["crashes"], r["crashes_frames_taken"], r["crashes_frames_lost"],
         r["crashes_frames_duplicated"], r["crashes_frames_replayed"],
         r["crash_recovery_s_median"]),
    ]  # fmt: skip
    print(f"Ledger at {r['rate_hz']:g} Hz, fifo/block, {r['network']}, standby {r['standby']}")
    heads = ("count", "taken", "lost", "twice", "replayed", "median s")
    widths = (6, 8, 6, 6, 9, 9)
    print(f"{'':<14} " + " ".join(f"{h:>{w}}" for h, w in zip(heads, widths, strict=True)))
    for name, *vals in rows:
        print(f"{name:<14} " + " ".join(f"{v:>{w}}" for v, w in zip(vals, widths, strict=True)))
    print("target: frames lost over the planned moves = 0")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(r, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
