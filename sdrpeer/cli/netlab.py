"""`sdrpeer lab fault`, `lab partition` and `lab heal`: real network faults in a namespace lab.

    sdrpeer lab fault robot-2 loss 30%        drop 30 % of the packets arriving at robot-2
    sdrpeer lab fault robot-2 bandwidth 1mbit shape robot-2's link (both ways) with tc tbf
    sdrpeer lab fault robot-2 clear           remove robot-2's loss and bandwidth faults
    sdrpeer lab partition robot-1,robot-2 / robot-3
    sdrpeer lab heal                          no partition, no fault

Each reads the lab's `netns.json` (written by `sdrpeer lab up --netns`) and runs the commands of
`sdrpeer.netlab.plan.NetPlan`. Delay and jitter have no command: this kernel has no netem.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sdrpeer.errors import SdrpeerError
from sdrpeer.units import parse_percent

if TYPE_CHECKING:
    from sdrpeer.netlab.plan import NetPlan


def add_fault_parsers(lab_sub: Any, where: argparse.ArgumentParser) -> None:
    """Register `lab fault`, `lab partition`, `lab heal`."""
    fault = lab_sub.add_parser("fault", parents=[where], help="loss or bandwidth on a robot")
    fault.add_argument("robot", help="robot-K")
    fault.add_argument("kind", choices=("loss", "bandwidth", "clear"))
    fault.add_argument("value", nargs="?", help="30%% for loss, 1mbit for bandwidth")
    fault.set_defaults(func=cmd_fault)
    part = lab_sub.add_parser("partition", parents=[where], help="cut the lab into groups")
    part.add_argument("groups", nargs="+", help="robot-1,robot-2 / robot-3")
    part.set_defaults(func=cmd_partition)
    heal = lab_sub.add_parser("heal", parents=[where], help="remove partitions and faults")
    heal.set_defaults(func=cmd_heal)


def _plan(lab_dir: Path) -> NetPlan:
    from sdrpeer.netlab import net  # noqa: PLC0415 - the parser stays light

    plan = net.load(lab_dir)
    if plan is None:
        raise SdrpeerError(f"{lab_dir} has no namespace lab (start one: sdrpeer lab up --netns)")
    net.require_tools()
    return plan


def parse_groups(words: list[str]) -> list[list[str]]:
    """["robot-1,robot-2", "/", "robot-3"] (or "robot-1,robot-2/robot-3") -> groups."""
    text = " ".join(words)
    groups = [
        [r.strip() for r in part.replace(" ", ",").split(",") if r.strip()]
        for part in text.split("/")
    ]
    if any(not g for g in groups):
        raise SdrpeerError(f"partition {text!r}: expected groups like robot-1,robot-2 / robot-3")
    return groups


def cmd_fault(args: argparse.Namespace) -> int:
    """sdrpeer lab fault ROBOT loss P | bandwidth R | clear."""
    from sdrpeer.netlab import net  # noqa: PLC0415 - the parser stays light

    plan = _plan(args.dir)
    try:
        if args.kind == "clear":
            net.run(plan.clear(args.robot), check=False)
            print(f"{args.robot}: faults cleared")
            return 0
        if args.value is None:
            raise SdrpeerError(f"lab fault {args.robot} {args.kind}: give a value (30% or 1mbit)")
        if args.kind == "loss":
            ratio = parse_percent(args.value) / 100
            net.run(plan.loss(args.robot, ratio))
            print(f"{args.robot}: {100 * ratio:g}% of arriving packets dropped")
        else:
            net.run(plan.bandwidth(args.robot, args.value))
            print(f"{args.robot}: link shaped to {args.value}")
    except ValueError as exc:
        raise SdrpeerError(str(exc)) from None
    return 0


def cmd_partition(args: argparse.Namespace) -> int:
    """sdrpeer lab partition A,B / C."""
    from sdrpeer.netlab import net  # noqa: PLC0415 - the parser stays light

    plan = _plan(args.dir)
    groups = parse_groups(args.groups)
    try:
        net.run(plan.partition(groups))
    except ValueError as exc:
        raise SdrpeerError(str(exc)) from None
    print("partitioned: " + " / ".join(",".join(g) for g in groups))
    return 0


def cmd_heal(args: argparse.Namespace) -> int:
    """sdrpeer lab heal."""
    from sdrpeer.netlab import net  # noqa: PLC0415 - the parser stays light

    net.run(_plan(args.dir).heal(), check=False)
    print("healed: no partition, no fault")
    return 0
