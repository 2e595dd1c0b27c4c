"""Running the namespace lab's commands (root): create, fault, partition, heal, destroy.

How it works: `create(lab_dir, robots)` picks a free lab id (no bridge `sdrbr<id>` yet), writes
`netns.json` (the id and the robot count) *before* touching the network, then runs
`NetPlan.setup()`; if a command fails, what was made is removed again and the error names the
command and what it printed. Because the file comes first, `destroy(lab_dir)` can remove
everything after a crash of the lab at any point. `destroy` runs every teardown command whatever
fails (a part may already be gone) and then deletes the file; `sweep()` removes every namespace,
bridge and veth with the lab's names (for `sdrpeer lab down --all-netns`, when the file is lost).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from collections.abc import Iterable
from pathlib import Path
from typing import Final

from sdrpeer.errors import SdrpeerError
from sdrpeer.netlab.plan import BRIDGE_PREFIX, NS_PREFIX, NetPlan

__all__ = ["create", "destroy", "load", "require_tools", "run", "sweep"]

STATE_FILE: Final = "netns.json"
TOOLS: Final = {"ip": "iproute2", "iptables": "iptables", "tc": "iproute2"}
TIMEOUT: Final = 15.0


def require_tools() -> None:
    """SdrpeerError unless this is root with ip, iptables and tc installed."""
    if os.geteuid() != 0:
        raise SdrpeerError("the network-namespace lab needs root (ip netns, iptables, tc)")
    missing = sorted({pkg for tool, pkg in TOOLS.items() if shutil.which(tool) is None})
    if missing:
        raise SdrpeerError(f"the network-namespace lab needs: apt-get install {' '.join(missing)}")


def run(commands: Iterable[list[str]], *, check: bool = True) -> list[str]:
    """Run each command; the failures' messages (raised at the first one when `check`)."""
    failures = []
    for argv in commands:
        try:
            done = subprocess.run(
                argv, capture_output=True, text=True, timeout=TIMEOUT, check=False
            )
            problem = None if done.returncode == 0 else (done.stderr or done.stdout).strip()
        except (OSError, subprocess.TimeoutExpired) as exc:
            problem = str(exc)
        if problem is not None:
            message = f"{' '.join(argv)}: {problem}"
            if check:
                raise SdrpeerError(message)
            failures.append(message)
    return failures


def _bridge_exists(name: str) -> bool:
    done = subprocess.run(["ip", "link", "show", name], capture_output=True, check=False)
    return done.returncode == 0


def _free(plan: NetPlan) -> bool:
    """No link of `plan` exists yet (a crashed lab may have left some behind)."""
    names = [plan.bridge, *(plan.veth(r) for r in plan.names())]
    return not any(_bridge_exists(name) for name in names)


def load(lab_dir: Path) -> NetPlan | None:
    """The lab's network as recorded in `netns.json`, or None."""
    try:
        doc = json.loads((lab_dir / STATE_FILE).read_text())
        return NetPlan(int(doc["id"]), int(doc["robots"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _claim(robots: int) -> NetPlan:
    """The first free lab id, claimed by making its bridge: two labs built at once (two `lab up
    --netns`, or tests side by side) cannot both get an id, since only one `ip link add` of a
    name succeeds."""
    for lab_id in range(1, 251):
        plan = NetPlan(lab_id, robots)
        if not _free(plan):
            continue
        failed = run(plan.setup()[:1], check=False)
        if not failed:
            return plan
        if "exists" not in failed[0]:  # not a race lost to another lab: say what went wrong
            raise SdrpeerError(failed[0])
    raise SdrpeerError("no free lab id: 250 namespace labs exist (sdrpeer lab down --all-netns)")


def create(lab_dir: Path, robots: int) -> NetPlan:
    """Build a fresh network for `robots` robots; recorded in lab_dir/netns.json first."""
    require_tools()
    existing = load(lab_dir)
    if existing is not None:
        destroy(lab_dir)
    plan = _claim(robots)
    try:
        lab_dir.mkdir(parents=True, exist_ok=True)
        (lab_dir / STATE_FILE).write_text(json.dumps({"id": plan.lab_id, "robots": robots}) + "\n")
    except OSError:  # nothing would record the claim: give the bridge back
        run(plan.teardown(), check=False)
        raise
    try:
        run(plan.setup()[1:])  # the bridge is made: that was the claim
    except SdrpeerError:
        destroy(lab_dir)
        raise
    return plan


def destroy(lab_dir: Path) -> list[str]:
    """Remove the lab's namespaces, veths and bridge; what could not be removed (usually none)."""
    plan = load(lab_dir)
    if plan is None:
        return []
    run(plan.teardown(), check=False)  # a part may already be gone: that is fine
    left = [n for n in _namespaces() if n.startswith(f"{NS_PREFIX}{plan.lab_id}-")]
    if _bridge_exists(plan.bridge):
        left.append(plan.bridge)
    (lab_dir / STATE_FILE).unlink(missing_ok=True)
    return left


def _namespaces() -> list[str]:
    done = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=False)
    return [line.split()[0] for line in done.stdout.splitlines() if line.strip()]


def sweep() -> list[str]:
    """Remove every namespace and bridge with the lab's prefixes; what was removed."""
    removed = []
    for ns in _namespaces():
        if ns.startswith(NS_PREFIX) and not run([["ip", "netns", "del", ns]], check=False):
            removed.append(ns)
    links = subprocess.run(
        ["ip", "-o", "link", "show", "type", "bridge"], capture_output=True, text=True, check=False
    ).stdout
    veths = subprocess.run(
        ["ip", "-o", "link", "show", "type", "veth"], capture_output=True, text=True, check=False
    ).stdout
    for line in [*links.splitlines(), *veths.splitlines()]:
        name = line.split(":")[1].strip().split("@")[0] if ":" in line else ""
        ours = name.startswith(BRIDGE_PREFIX) or re.fullmatch(r"sdr\d+r\d+", name)
        if ours and not run([["ip", "link", "del", name]], check=False):
            removed.append(name)
    return removed
