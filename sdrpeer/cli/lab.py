"""`sdrpeer lab up|down|status` (and the demo parser): the local lab from the command line.

Without `--detach`, `lab up` stays in the foreground and redraws the members table once a second
(in place on a terminal, appended when piped) until `--seconds` pass or Ctrl-C, then stops every
agent; it also carries out the scenario's lab steps (agent kill, stop, restart, partition, heal:
`sdrpeer.lab.script`) on time, so a scenario with such steps refuses `--detach` (nobody would be
left to run them). `demo` (the paper's experiment) lives in `sdrpeer.cli.demo`.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, TextIO

from sdrpeer.cli.format import format_members, render_table, want_color
from sdrpeer.cli.netlab import add_fault_parsers
from sdrpeer.client import AgentClient
from sdrpeer.config import LAB_PRESET, PRESET_NAMES, presets_epilog
from sdrpeer.errors import ApiError, SdrpeerError
from sdrpeer.lab.files import DEFAULT_DIR
from sdrpeer.lab.procs import lab_down, lab_status

if TYPE_CHECKING:
    from sdrpeer.lab.up import RunningLab, UpOptions

if TYPE_CHECKING:  # the scenario parser loads only for a lab that has a scenario
    from sdrpeer.lab.script import Conductor

REFRESH = 1.0
STEPS_SHOWN = 5
"""Scenario steps carried out that a frame lists (the last ones)."""


def add_lab_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register `lab` (up, down, status) and `demo`."""
    lab = sub.add_parser("lab", help="N agents on this machine (loopback)")
    lab_sub = lab.add_subparsers(dest="lab_command", required=True, metavar="ACTION")
    where = argparse.ArgumentParser(add_help=False)
    where.add_argument("--dir", type=Path, default=DEFAULT_DIR, help="lab directory")
    up = lab_sub.add_parser(
        "up",
        parents=[where],
        help="start a lab",
        description="Start N agents on this machine (one virtual robot each).",
        epilog=presets_epilog(LAB_PRESET),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    up.add_argument("--robots", type=int, default=3, metavar="N", help="how many (default 3)")
    up.add_argument("--detach", action="store_true", help="leave the agents running and return")
    up.add_argument(
        "--preset",
        choices=PRESET_NAMES,
        default=LAB_PRESET,
        help=f"every agent's timers (default {LAB_PRESET}; the list below)",
    )
    up.add_argument("--robot-files", type=Path, metavar="DIR", help="robot-K.yaml files")
    up.add_argument(
        "--scenario",
        type=Path,
        metavar="FILE",
        help="scenario for every agent; its agent/partition/heal steps run here (no --detach)",
    )
    up.add_argument("--seconds", type=float, metavar="S", help="stop after S s (default: Ctrl-C)")
    up.add_argument("--timeout", type=float, default=20.0, metavar="S", help="start timeout")
    up.add_argument(
        "--netns", action="store_true", help="each robot in its own network namespace (root)"
    )
    up.add_argument(
        "--discover",
        action="store_true",
        help="robots find each other by mDNS, no --join (with --netns: loopback has no multicast)",
    )
    up.add_argument(
        "--allow-launchers",
        "--allow-launcher",
        dest="allow_launchers",
        action="append",
        default=[],
        metavar="NAME",
        help="a launcher every robot's hosts may use besides python (exec, script, a plugin), "
        "as `sdrpeer agent --allow-launcher`: off unless named; repeat",
    )
    up.set_defaults(func=cmd_lab_up)
    down = lab_sub.add_parser("down", parents=[where], help="stop the lab's agents")
    down.add_argument(
        "--all-netns", action="store_true", help="also remove every lab namespace and bridge"
    )
    down.set_defaults(func=cmd_lab_down)
    add_fault_parsers(lab_sub, where)
    chaos = lab_sub.add_parser("chaos", help="a seeded chaos soak with invariants checked")
    chaos.add_argument("--robots", type=int, default=10, metavar="N")
    chaos.add_argument("--components", type=int, default=20, metavar="N")
    chaos.add_argument("--minutes", type=float, default=1.0, metavar="M")
    chaos.add_argument("--seed", type=int, default=1)
    chaos.add_argument(
        "--loopback", action="store_true", help="no namespaces (no partitions, loss)"
    )
    chaos.add_argument("--json", type=Path, metavar="FILE", help="also write the report as JSON")
    chaos.add_argument(
        "--keep", type=Path, metavar="DIR", help="run the lab in DIR and keep its logs there"
    )
    chaos.set_defaults(func=cmd_lab_chaos)
    status = lab_sub.add_parser("status", parents=[where], help="the lab's agents")
    status.add_argument("--json", action="store_true", help="print JSON")
    status.set_defaults(func=cmd_lab_status)
    from sdrpeer.cli.demo import add_demo_parser  # noqa: PLC0415 - only when parsing

    add_demo_parser(sub)


def _say(text: str) -> None:
    print(text, flush=True)


def print_started(running: RunningLab) -> None:
    """The API URL, gossip address and log of every robot, plus what to type next."""
    rows = [[r.name, str(r.api), str(r.gossip), str(r.pid), r.log] for r in running.lab.robots]
    _say(render_table(["ROBOT", "API", "GOSSIP", "PID", "LOG"], rows))


def frame(
    running: RunningLab,
    elapsed: float,
    seconds: float | None,
    color: bool,
    steps: Sequence[tuple[float, str]] = (),
) -> str:
    """One screenful: a header, the members table (from the first agent that answers), problems,
    the last scenario steps carried out."""
    limit = f" of {seconds:g}" if seconds is not None else ""
    lines = [
        f"lab {running.lab_dir}: {len(running.lab.robots)} robots, "
        f"{elapsed:.0f}{limit} s  (Ctrl-C to stop)"
    ]
    error = "no agent is running"
    for robot in running.lab.robots:
        if not robot.api:
            continue
        try:
            members = AgentClient(robot.api, timeout=0.5).members()
        except ApiError as exc:
            error = str(exc)
            continue
        lines += [f"members as {robot.name} sees them:", format_members(members, color=color)]
        break
    else:
        lines.append(error)
    lines += running.problems()
    lines += [f"scenario {t:.1f}s: {what}" for t, what in steps[-STEPS_SHOWN:]]
    return "\n".join(lines)


def watch(
    running: RunningLab,
    seconds: float | None,
    out: TextIO,
    *,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    conductor: Conductor | None = None,
) -> None:
    """Redraw the frame every REFRESH s (in place on a TTY) until `seconds` pass or Ctrl-C; the
    `conductor`'s due scenario steps run before each frame, and no later than they are due."""
    tty = out.isatty()
    color = want_color(tty, os.environ)
    start = clock()
    drawn = 0
    try:
        while True:
            elapsed = clock() - start
            if conductor is not None:
                conductor.tick()
            steps = () if conductor is None else conductor.done
            text = frame(running, elapsed, seconds, color, steps)
            if tty and drawn:
                out.write(f"\x1b[{drawn}F\x1b[J")
            elif drawn:
                out.write("\n")
            out.write(text + "\n")
            out.flush()
            drawn = text.count("\n") + 1
            if seconds is not None and elapsed >= seconds:
                return
            remaining = REFRESH if seconds is None else min(REFRESH, seconds - elapsed)
            step_in = None if conductor is None else conductor.next_in()
            if step_in is not None:
                remaining = min(remaining, step_in)
            sleep(max(remaining, 0.0))
    except KeyboardInterrupt:
        out.write("\n")


def _terminate(signum: int, frame: FrameType | None) -> None:
    """SIGTERM stops a foreground lab the way Ctrl-C does (cleanly)."""
    raise KeyboardInterrupt


def run_lab(options: UpOptions, *, detach: bool, seconds: float | None) -> int:
    """Start the lab; detach, or watch it and stop it when done."""
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        return _run_lab(options, detach=detach, seconds=seconds)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run_lab(options: UpOptions, *, detach: bool, seconds: float | None) -> int:
    from sdrpeer.lab import script  # noqa: PLC0415 - YAML and the scenario parser: only here
    from sdrpeer.lab.up import start_lab  # noqa: PLC0415 - the parser stays light

    steps = [] if options.scenario is None else script.lab_steps(options.scenario)
    if steps:
        where = str(options.scenario)
        script.check(steps, options.robots, netns=options.netns, where=where)
        if detach:
            raise SdrpeerError(
                f"{where}: its agent/partition/heal steps run in the lab command: "
                "leave out --detach (add --seconds S to stop after S s)"
            )
    running = start_lab(options, _say)
    print_started(running)
    if detach:
        _say(
            f"agents run in the background; try: sdrpeer members --lab-dir {options.lab_dir}\n"
            f"stop them with: sdrpeer lab down --dir {options.lab_dir}"
        )
        return 0
    conductor = script.Conductor(running, steps, say=lambda _: None) if steps else None
    try:
        watch(running, seconds, sys.stdout, conductor=conductor)
    finally:
        _say("stopping the lab")
        for line in running.stop():
            _say(f"  {line}")
    return 0


def cmd_lab_up(args: argparse.Namespace) -> int:
    """sdrpeer lab up."""
    from sdrpeer.lab.up import UpOptions  # noqa: PLC0415 - the parser stays light

    options = UpOptions(
        robots=args.robots,
        lab_dir=args.dir,
        preset=args.preset,
        robot_files=args.robot_files,
        scenario=args.scenario,
        timeout=args.timeout,
        netns=args.netns,
        discover=args.discover,
        allow_launchers=tuple(args.allow_launchers),
    )
    return run_lab(options, detach=args.detach, seconds=args.seconds)


def cmd_lab_down(args: argparse.Namespace) -> int:
    """sdrpeer lab down."""
    from sdrpeer.netlab import net  # noqa: PLC0415 - the parser stays light

    has_net = (args.dir / net.STATE_FILE).exists()
    try:
        for line in lab_down(args.dir):
            _say(line)
    except SdrpeerError:
        if not (has_net or args.all_netns):
            raise
    if has_net:
        left = net.destroy(args.dir)
        _say(f"network removed{'; left: ' + ', '.join(left) if left else ''}")
    if args.all_netns:
        net.require_tools()
        removed = net.sweep()
        _say(f"removed {len(removed)} lab namespaces and bridges")
    return 0


def cmd_lab_status(args: argparse.Namespace) -> int:
    """sdrpeer lab status."""
    status = lab_status(args.dir)
    if args.json:
        print(json.dumps(status, indent=2, sort_keys=True))
        return 0
    rows = [
        [s["name"], str(s["pid"]), "running" if s["running"] else "stopped", str(s["api"])]
        for s in status
    ]
    _say(render_table(["ROBOT", "PID", "PROCESS", "API"], rows))
    return 0 if all(s["running"] for s in status) else 1


def cmd_lab_chaos(args: argparse.Namespace) -> int:
    """sdrpeer lab chaos: exit 1 when an invariant was violated."""
    from sdrpeer.chaos.run import ChaosOptions, format_report, run_chaos  # noqa: PLC0415

    options = ChaosOptions(
        robots=args.robots,
        components=args.components,
        minutes=args.minutes,
        seed=args.seed,
        netns=False if args.loopback else None,
        lab_dir=args.keep,
    )
    report = run_chaos(options, _say)
    _say(format_report(report))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2))
    return 1 if report["violations"] else 0
