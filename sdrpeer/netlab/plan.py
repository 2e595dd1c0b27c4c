"""The network-namespace lab as commands: names, addresses, and the `ip`/`iptables`/`tc` argv
lists that build it, break it and tear it down (pure: nothing here runs a command).

How it works: lab `id` (1-250) owns the subnet 10.213.<id>.0/24 and a bridge `sdrbr<id>` on the
host holding 10.213.<id>.254. Robot k lives in the namespace `sdrlab<id>-robot-k` with one veth
pair: `sdr<id>r<k>` on the host, enslaved to the bridge, and `eth0` inside with 10.213.<id>.<k>
(k = 1..200). The agent, its API and its component hosts bind that address, so everything a
robot sends crosses the bridge: faults act on the real network.

- loss P: `iptables ... -m statistic --mode random --probability P -j DROP` on the robot's INPUT
  (in its own chain, SDRPEER-FAULT): every packet *to* that robot from another robot is dropped
  with probability P, so with the fault on every robot each link loses P in each direction
  (what comes from the host — the command line, a soak's observer — is always let through);
- bandwidth R: `tc tbf` on both ends of the robot's veth (into and out of the robot);
- partition: each robot of a group drops (SDRPEER-PART) what comes from the other groups;
- heal: both chains flushed and every qdisc removed; down: the namespaces (their veth ends and
  rules go with them) and the bridge deleted. The kernel has no netem: delay and jitter faults
  stay at the application level (the virtual robot's scenario).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

__all__ = ["FAULT_CHAIN", "PART_CHAIN", "NetPlan", "parse_rate"]

FAULT_CHAIN: Final = "SDRPEER-FAULT"
PART_CHAIN: Final = "SDRPEER-PART"
MAX_ROBOTS: Final = 200
NS_PREFIX: Final = "sdrlab"
BRIDGE_PREFIX: Final = "sdrbr"

Argv = list[str]


def parse_rate(text: str) -> str:
    """A tc rate as people write it (1mbit, 512kbit, 2Mbit, 100kbps); ValueError otherwise."""
    m = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([kmg]?)(bit|bps)", text.strip(), re.IGNORECASE)
    if not m or float(m.group(1)) <= 0:
        raise ValueError(f"bandwidth {text!r}: expected a rate like 1mbit, 512kbit or 100kbps")
    return f"{m.group(1)}{m.group(2).lower()}{m.group(3).lower()}"


@dataclass(frozen=True, slots=True)
class NetPlan:
    """The names and addresses of lab `lab_id` with `robots` robots."""

    lab_id: int
    robots: int

    def __post_init__(self) -> None:
        if not 1 <= self.lab_id <= 250:
            raise ValueError(f"lab id {self.lab_id}: expected 1-250")
        if not 1 <= self.robots <= MAX_ROBOTS:
            raise ValueError(f"{self.robots} robots: a namespace lab holds 1-{MAX_ROBOTS}")

    @property
    def bridge(self) -> str:
        """The host's bridge."""
        return f"{BRIDGE_PREFIX}{self.lab_id}"

    @property
    def gateway(self) -> str:
        """The host's address on the bridge."""
        return f"10.213.{self.lab_id}.254"

    def index(self, robot: str) -> int:
        """k of robot-k; ValueError for a robot not in this lab."""
        m = re.fullmatch(r"robot-(\d+)", robot)
        if not m or not 1 <= int(m.group(1)) <= self.robots:
            raise ValueError(
                f"{robot!r} is not a robot of this lab (robot-1 .. robot-{self.robots})"
            )
        return int(m.group(1))

    def names(self) -> list[str]:
        """robot-1 .. robot-N."""
        return [f"robot-{k}" for k in range(1, self.robots + 1)]

    def namespace(self, robot: str) -> str:
        """The network namespace of a robot."""
        return f"{NS_PREFIX}{self.lab_id}-robot-{self.index(robot)}"

    def veth(self, robot: str) -> str:
        """The host end of a robot's veth pair."""
        return f"sdr{self.lab_id}r{self.index(robot)}"

    def address(self, robot: str) -> str:
        """The robot's address on the bridge."""
        return f"10.213.{self.lab_id}.{self.index(robot)}"

    def in_ns(self, robot: str, *argv: str) -> Argv:
        """`argv` run inside the robot's namespace."""
        return ["ip", "netns", "exec", self.namespace(robot), *argv]

    # -- build and tear down -------------------------------------------------------------------

    def setup(self) -> list[Argv]:
        """Every command that builds the lab's network."""
        out: list[Argv] = [
            ["ip", "link", "add", self.bridge, "type", "bridge"],
            ["ip", "addr", "add", f"{self.gateway}/24", "dev", self.bridge],
            ["ip", "link", "set", self.bridge, "up"],
        ]
        for robot in self.names():
            ns, veth = self.namespace(robot), self.veth(robot)
            out += [
                ["ip", "netns", "add", ns],
                ["ip", "link", "add", veth, "type", "veth", "peer", "name", "eth0", "netns", ns],
                ["ip", "link", "set", veth, "master", self.bridge],
                ["ip", "link", "set", veth, "up"],
                ["ip", "-n", ns, "addr", "add", f"{self.address(robot)}/24", "dev", "eth0"],
                ["ip", "-n", ns, "link", "set", "eth0", "up"],
                ["ip", "-n", ns, "link", "set", "lo", "up"],
                self.in_ns(robot, "iptables", "-N", FAULT_CHAIN),
                self.in_ns(robot, "iptables", "-N", PART_CHAIN),
                # the lab's own traffic (the host: CLI, soak observers) is never faulted
                self.in_ns(robot, "iptables", "-A", "INPUT", "-s", self.gateway, "-j", "ACCEPT"),
                self.in_ns(robot, "iptables", "-A", "INPUT", "-j", PART_CHAIN),
                self.in_ns(robot, "iptables", "-A", "INPUT", "-j", FAULT_CHAIN),
            ]
        return out

    def teardown(self) -> list[Argv]:
        """Every command that removes it (each may fail if that part is already gone)."""
        out = [["ip", "netns", "del", self.namespace(r)] for r in self.names()]
        out += [["ip", "link", "del", self.veth(r)] for r in self.names()]
        out.append(["ip", "link", "del", self.bridge])
        return out

    # -- faults ----------------------------------------------------------------------------------

    def loss(self, robot: str, ratio: float, *, spare_host: bool = False) -> list[Argv]:
        """Drop `ratio` (0..1) of the packets arriving at the robot (replaces an earlier loss);
        `spare_host`: not those from the host (the gateway), e.g. an observer's API calls."""
        if not 0.0 <= ratio <= 1.0:
            raise ValueError(f"loss {ratio:g}: expected 0% to 100%")
        out = [self.in_ns(robot, "iptables", "-F", FAULT_CHAIN)]
        if ratio > 0 and spare_host:
            out.append(
                self.in_ns(robot, "iptables", "-A", FAULT_CHAIN, "-s", self.gateway, "-j", "RETURN")
            )
        if ratio > 0:
            out.append(
                self.in_ns(
                    robot,
                    "iptables",
                    "-A",
                    FAULT_CHAIN,
                    "-m",
                    "statistic",
                    "--mode",
                    "random",
                    "--probability",
                    f"{ratio:.4f}",
                    "-j",
                    "DROP",
                )
            )
        return out

    def bandwidth(self, robot: str, rate: str) -> list[Argv]:
        """Shape the robot's link to `rate` both ways (tc tbf on each end of its veth)."""
        rate = parse_rate(rate)
        tbf = ["tbf", "rate", rate, "burst", "32kbit", "latency", "400ms"]
        return [
            ["tc", "qdisc", "replace", "dev", self.veth(robot), "root", *tbf],
            self.in_ns(robot, "tc", "qdisc", "replace", "dev", "eth0", "root", *tbf),
        ]

    def clear(self, robot: str) -> list[Argv]:
        """Remove the robot's loss and bandwidth faults (deleting an absent qdisc may fail)."""
        return [
            self.in_ns(robot, "iptables", "-F", FAULT_CHAIN),
            ["tc", "qdisc", "del", "dev", self.veth(robot), "root"],
            self.in_ns(robot, "tc", "qdisc", "del", "dev", "eth0", "root"),
        ]

    def partition(self, groups: Sequence[Sequence[str]]) -> list[Argv]:
        """Cut the lab into `groups`: each robot drops what comes from robots of other groups
        (robots named in no group stay connected to everyone)."""
        seen: set[str] = set()
        for group in groups:
            for robot in group:
                self.index(robot)
                if robot in seen:
                    raise ValueError(f"{robot} is in two groups")
                seen.add(robot)
        if len(groups) < 2:
            raise ValueError("a partition needs at least two groups: A,B / C")
        out: list[Argv] = [self.in_ns(r, "iptables", "-F", PART_CHAIN) for r in self.names()]
        for group in groups:
            others = ",".join(self.address(r) for g in groups if g is not group for r in g)
            for robot in group:  # one command a robot (a busy machine spawns processes slowly)
                out.append(
                    self.in_ns(robot, "iptables", "-A", PART_CHAIN, "-s", others, "-j", "DROP")
                )
        return out

    def heal(self) -> list[Argv]:
        """No partition and no fault left (removing an absent qdisc may fail)."""
        out = [self.in_ns(r, "iptables", "-F", PART_CHAIN) for r in self.names()]
        for robot in self.names():
            out += self.clear(robot)
        return out
