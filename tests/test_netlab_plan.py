"""The namespace lab's commands (pure): names, addresses, setup, faults, partitions, heal."""

from __future__ import annotations

import pytest

from sdrpeer.cli.netlab import parse_groups
from sdrpeer.errors import SdrpeerError
from sdrpeer.netlab.plan import FAULT_CHAIN, PART_CHAIN, NetPlan, parse_rate

PLAN = NetPlan(7, 3)


def test_names_and_addresses() -> None:
    assert PLAN.names() == ["robot-1", "robot-2", "robot-3"]
    assert (PLAN.bridge, PLAN.gateway) == ("sdrbr7", "10.213.7.254")
    assert PLAN.namespace("robot-2") == "sdrlab7-robot-2"
    assert PLAN.veth("robot-2") == "sdr7r2"
    assert PLAN.address("robot-3") == "10.213.7.3"
    big = NetPlan(250, 200)
    assert all(len(big.veth(r)) <= 15 for r in big.names())  # IFNAMSIZ
    for bad in ("robot-4", "robot-0", "rover-1"):
        with pytest.raises(ValueError, match="not a robot of this lab"):
            PLAN.index(bad)
    with pytest.raises(ValueError, match="1-250"):
        NetPlan(251, 3)
    with pytest.raises(ValueError, match="1-200"):
        NetPlan(1, 201)


def test_setup_puts_each_robot_in_its_namespace_on_the_bridge() -> None:
    cmds = PLAN.setup()
    assert cmds[0] == ["ip", "link", "add", "sdrbr7", "type", "bridge"]
    assert ["ip", "netns", "add", "sdrlab7-robot-1"] in cmds
    assert ["ip", "link", "set", "sdr7r1", "master", "sdrbr7"] in cmds
    assert ["ip", "-n", "sdrlab7-robot-3", "addr", "add", "10.213.7.3/24", "dev", "eth0"] in cmds
    jump = ["ip", "netns", "exec", "sdrlab7-robot-2", "iptables", "-A", "INPUT", "-j"]
    assert [*jump, FAULT_CHAIN] in cmds
    assert [*jump, PART_CHAIN] in cmds
    assert PLAN.teardown()[-1] == ["ip", "link", "del", "sdrbr7"]


def test_loss_replaces_the_robots_fault_rule() -> None:
    flush, rule = PLAN.loss("robot-2", 0.3)
    assert flush[-3:] == ["iptables", "-F", FAULT_CHAIN]
    assert rule[:4] == ["ip", "netns", "exec", "sdrlab7-robot-2"]
    assert rule[4:] == [
        "iptables", "-A", FAULT_CHAIN, "-m", "statistic", "--mode", "random",
        "--probability", "0.3000", "-j", "DROP",
    ]  # fmt: skip
    assert PLAN.loss("robot-2", 0.0) == [flush]  # 0 %: only the flush
    _, spare, drop = PLAN.loss("robot-2", 0.3, spare_host=True)  # an observer's calls pass
    assert spare[4:] == ["iptables", "-A", FAULT_CHAIN, "-s", "10.213.7.254", "-j", "RETURN"]
    assert drop == rule
    with pytest.raises(ValueError, match="0% to 100%"):
        PLAN.loss("robot-2", 1.5)


def test_bandwidth_shapes_both_ends() -> None:
    host, inside = PLAN.bandwidth("robot-1", "1Mbit")
    assert host[:6] == ["tc", "qdisc", "replace", "dev", "sdr7r1", "root"]
    assert host[6:9] == ["tbf", "rate", "1mbit"]
    assert inside[4:10] == ["tc", "qdisc", "replace", "dev", "eth0", "root"]


@pytest.mark.parametrize(
    ("text", "rate"), [("1mbit", "1mbit"), ("512kbit", "512kbit"), ("2.5 Mbit", "2.5mbit"),
                       ("100kbps", "100kbps")],
)  # fmt: skip
def test_rates(text: str, rate: str) -> None:
    assert parse_rate(text) == rate


@pytest.mark.parametrize("text", ["fast", "1mb", "0mbit", "-1kbit", ""])
def test_bad_rates(text: str) -> None:
    with pytest.raises(ValueError, match="expected a rate like 1mbit"):
        parse_rate(text)


def test_partition_drops_what_comes_from_the_other_side() -> None:
    cmds = PLAN.partition([["robot-1"], ["robot-2", "robot-3"]])
    flushes = [c for c in cmds if c[-2:] == ["-F", PART_CHAIN]]
    assert len(flushes) == 3  # every robot starts from no partition
    drops = [(c[3], c[-3]) for c in cmds if c[-1] == "DROP"]
    assert sorted(drops) == [  # one rule a robot, naming every source across the cut
        ("sdrlab7-robot-1", "10.213.7.2,10.213.7.3"),
        ("sdrlab7-robot-2", "10.213.7.1"),
        ("sdrlab7-robot-3", "10.213.7.1"),
    ]
    with pytest.raises(ValueError, match="two groups"):
        PLAN.partition([["robot-1", "robot-2"]])
    with pytest.raises(ValueError, match="robot-1 is in two groups"):
        PLAN.partition([["robot-1"], ["robot-1", "robot-2"]])


def test_heal_flushes_partitions_and_faults() -> None:
    cmds = PLAN.heal()
    assert sum(c[-2:] == ["-F", PART_CHAIN] for c in cmds) == 3
    assert sum(c[-2:] == ["-F", FAULT_CHAIN] for c in cmds) == 3
    assert sum(c[:3] == ["tc", "qdisc", "del"] for c in cmds) == 3


def test_partition_groups_as_typed() -> None:
    assert parse_groups(["robot-1,robot-2", "/", "robot-3"]) == [
        ["robot-1", "robot-2"],
        ["robot-3"],
    ]
    assert parse_groups(["robot-1/robot-2"]) == [["robot-1"], ["robot-2"]]
    with pytest.raises(SdrpeerError, match="expected groups"):
        parse_groups(["robot-1", "/"])
