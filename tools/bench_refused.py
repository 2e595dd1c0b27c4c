"""A sender its receiver refuses: how soon the agent hears why, and how soon its host exits.

Usage: python tools/bench_refused.py [--runs 5] [--json out.json]

Each run starts two hosts exactly as an agent does (`sdrpeer.runtime.supervisor.Supervisor`,
the fast_test timers but the lan preset's stop deadlines: `exit` 5 s, SIGTERM 3 s), each with
its own data key, so the receiver's proof does not hold for the sender: a
`components.ledger:Sequencer` (it writes with `send()`) connected with
`push: fifo, buffer: 4, full: block` to a `components.ledger:Ledger` over TCP. Figures:

- *refused -> agent*: from the `connect` command's reply to the supervisor's `on_refused` hook
  (where the agent adds its `conn.refused` event, in the same call): the sender dials at once,
  is refused, and its host reports why. Target (issue 30 item 5): <= 1 s.
- *exit*: once the sender's queue is full (its component waits in `send()`), the supervisor's
  `stop()` (the `exit` command; SIGTERM only past its 5 s deadline) until the host process
  ended, and its exit code. Target: <= 1 s, exit code 0 (before the fix: the 5 s finalize
  deadline, then exit code 1).

Medians and maxima are quoted.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchout import finish

from sdrpeer.control.messages import Activate, Conn, Connect, Refused
from sdrpeer.runtime.config import fast_test as supervisor_fast
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.runtime.supervisor import Supervisor

TARGET_S = 1.0
BUFFER = 4
POLICY = {"push": "fifo", "buffer": BUFFER, "full": "block"}


async def started(name: str, target: str, key: bytes, data_dir: Path) -> Supervisor:
    """A supervised host of `target` holding data key `key`, once it is INACTIVE."""
    spec = InstanceSpec.from_json({"name": name, "target": target, "desired": "inactive"})
    config = supervisor_fast().with_(exit_timeout=5.0, term_timeout=3.0)
    sup = Supervisor(spec, data_dir / name, config, data_keys=lambda: (key,))
    sup.start()
    async with asyncio.timeout(30.0):
        while sup.start_latency is None:  # noqa: ASYNC110 (the supervisor sets it)
            await asyncio.sleep(0.002)
    return sup


async def one_run(data_dir: Path) -> dict[str, Any]:
    """One refused sender: the seconds to the agent's hook, to its host's exit, its code."""
    rec = await started("Rec", "components.ledger:Ledger", b"\x22" * 32, data_dir)
    pub = await started("Pub", "components.ledger:Sequencer", b"\x11" * 32, data_dir)
    heard: list[tuple[float, Refused]] = []
    pub.on_refused = lambda sup, report: heard.append((time.monotonic(), report))
    try:
        await rec.command(Activate())
        assert rec.hello is not None
        to = f"tcp://{rec.hello.data['tcp']}"
        await pub.command(Connect(Conn("c1", "out", to, "inp", POLICY)))
        connected = time.monotonic()
        await pub.command(Activate())
        async with asyncio.timeout(10.0):
            while not heard:  # noqa: ASYNC110 (the supervisor's hook appends)
                await asyncio.sleep(0.001)
            while pub.ports.get("out", {}).get("frames_out", 0) < BUFFER:  # noqa: ASYNC110
                await asyncio.sleep(0.005)  # the queue is full: send() waits from now on
        told_at, report = heard[0]
        asked = time.monotonic()
        await pub.stop()  # the agent's own stop: `exit`, then SIGTERM only past its deadline
        return {
            "refused_to_agent_s": told_at - connected,
            "error": report.error,
            "exit_s": time.monotonic() - asked,
            "exit_code": pub.last_exit,
        }
    finally:
        await asyncio.gather(pub.stop(), rec.stop())


async def measure(runs: int) -> dict[str, Any]:
    """Every run's figures, their medians and maxima."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(runs):
            rows.append(await one_run(Path(tmp) / f"run{i}"))
    told = [r["refused_to_agent_s"] for r in rows]
    exits = [r["exit_s"] for r in rows]
    return {
        "runs": rows,
        "refused_to_agent_median_s": statistics.median(told),
        "refused_to_agent_max_s": max(told),
        "exit_median_s": statistics.median(exits),
        "exit_max_s": max(exits),
        "exit_codes": sorted({r["exit_code"] for r in rows}),
        "target_s": TARGET_S,
    }


def report(result: dict[str, Any]) -> str:
    """The table."""
    lines = [
        f"{'figure':<34} {'median':>8} {'max':>8} {'target':>8}",
        f"{'refused -> agent (s)':<34} {result['refused_to_agent_median_s']:>8.3f} "
        f"{result['refused_to_agent_max_s']:>8.3f} {TARGET_S:>8.1f}",
        f"{'exit, blocked in send() (s)':<34} {result['exit_median_s']:>8.3f} "
        f"{result['exit_max_s']:>8.3f} {TARGET_S:>8.1f}",
        f"exit codes: {result['exit_codes']} over {len(result['runs'])} runs",
        f"reason: {result['runs'][0]['error']}",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, write --json."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)  # each run's refusals are logged as warnings
    result = asyncio.run(measure(args.runs))
    return finish(result, report(result), args.json)


if __name__ == "__main__":
    sys.exit(main())
