"""`sdrpeer demo`: the paper's experiment, twice, measured next to the paper's figures.

How it works: run 1 gives robot-2 the highest election priority (the allocator is elsewhere
than the robot that will lose its signal); run 2 gives it to robot-1, the paper's situation
(its load-balancing service sat on robot-1, which is why its recovery took ~11 s). Each run is
`sdrpeer.demo.experiment.run` in its own folder under `--out`; the table compares the runs with
the paper. `--fast` (for CI): 50 MB reserves instead of 500, the RSSI rule held 2 s instead of
6 s, the signal falls 12 s after start instead of 45 s. `--openrtm`: each run twice, the SDK
components and then their OpenRTM-aist RT-Component versions (components/openrtm/, the `openrtm`
launcher, examples/paper/system-openrtm.yaml), side by side in the table.
"""

from __future__ import annotations

import argparse
import json
import shutil
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sdrpeer.demo.experiment import RunOptions, RunResult

PAPER = {
    "deploy_to_active_s": "~16 s",
    "fault_to_condition_s": "~6 s (6 s rule)",
    "condition_to_active_s": "~11 s",
    "fault_to_active_s": "~17 s",
}
ROWS = (
    ("deploy -> all 5 ACTIVE", "deploy_to_active_s"),
    ("RSSI drop -> condition met", "fault_to_condition_s"),
    ("condition met -> moved ACTIVE", "condition_to_active_s"),
    ("RSSI drop -> moved ACTIVE", "fault_to_active_s"),
)


def add_demo_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register `sdrpeer demo`."""
    p = sub.add_parser("demo", help="the paper's experiment on this machine, measured")
    p.add_argument("--fast", action="store_true", help="small reserves, short sustain (CI)")
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder")
    p.add_argument(
        "--runs",
        choices=("both", "first", "second"),
        default="both",
        help="first: allocator off robot-1; second: allocator on robot-1 (default both)",
    )
    p.add_argument(
        "--openrtm",
        action="store_true",
        help="also run the RT-Component versions (OpenRTM-aist API, the openrtm launcher) "
        "and compare",
    )
    p.set_defaults(func=cmd_demo)


def options(out: Path, allocator_on: str, *, fast: bool, openrtm: bool = False) -> RunOptions:
    """The run's options (full: the paper's 500 MB and 6 s; `openrtm`: the RTC versions)."""
    from sdrpeer.demo.experiment import RunOptions  # noqa: PLC0415 - a lab, the loader: only here

    if fast:
        return RunOptions(
            out,
            allocator_on,
            reserve_mb=50,
            sustain_s=2.0,
            drop_at=12.0,
            after_s=3,
            openrtm=openrtm,
        )
    return RunOptions(out, allocator_on, openrtm=openrtm)


def table(results: dict[str, RunResult]) -> str:
    """The measured figures next to the paper's."""
    names = list(results)
    head = f"{'measure':<32}" + "".join(f"{n:>26}" for n in names) + f"{'paper (RPi 4)':>18}"
    lines = [head]
    for label, key in ROWS:
        cells = ""
        for n in names:
            v = getattr(results[n], key)
            cells += f"{'-' if v is None else f'{v:.2f} s':>26}"
        lines.append(f"{label:<32}{cells}{PAPER[key]:>18}")
    alloc = "".join(
        f"{(r.allocator_first or '?') + ' -> ' + (r.allocator_after or '?'):>26}"
        for r in results.values()
    )
    lines.append(f"{'allocator before -> after':<32}{alloc}")
    return "\n".join(lines)


def cmd_demo(args: argparse.Namespace) -> int:
    """Run the experiment and print the comparison."""
    from sdrpeer.demo.experiment import run  # noqa: PLC0415 - only here

    runs = {"first": "robot-2", "second": "robot-1"}
    chosen = list(runs) if args.runs == "both" else [args.runs]
    results: dict[str, RunResult] = {}
    kinds = (False, True) if args.openrtm else (False,)
    for name in chosen:
        for rtc in kinds:
            out = args.out / (f"run-{name}-openrtm" if rtc else f"run-{name}")
            shutil.rmtree(out, ignore_errors=True)
            where = "robot-1 (the robot that loses its signal)" if name == "second" else runs[name]
            what = " (OpenRTM RTCs)" if rtc else ""
            print(f"run {name}{what}: allocator first on {where}; output in {out}", flush=True)
            opts = options(out, runs[name], fast=args.fast, openrtm=rtc)
            result = run(opts, say=lambda s: print(s, flush=True))
            label = f"{name} RTC" if rtc else name
            results[f"{label} (alloc {runs[name]})"] = result
    text = table(results)
    print()
    print(text)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.txt").write_text(text + "\n")
    (args.out / "summary.json").write_text(
        json.dumps({k: asdict(r) for k, r in results.items()}, indent=2)
    )
    print(f"\ntimelines, Figs. 4-6 (PNG) and summaries in {args.out}/run-*/")
    return 0
