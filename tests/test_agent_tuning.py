"""The configuration tree: every preset is every part's same-named preset, every knob is
documented where it is declared and read somewhere, and an agent hands each part its sub-config."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import re
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.agent import timers as agent_timers
from sdrpeer.agent import tuning
from sdrpeer.agent.agent import Agent
from sdrpeer.api import config as api_config
from sdrpeer.cli.agent import add_agent_parser, agent_flag_values
from sdrpeer.cli.main import build_parser
from sdrpeer.config import LAB_PRESET, PRESET_NAMES, PRESETS_SAID, build_config
from sdrpeer.deploy import config as deploy
from sdrpeer.election import config as election
from sdrpeer.gossip import config as gossip
from sdrpeer.gossip.formulas import suspicion_min_timeout
from sdrpeer.lab.up import UpOptions
from sdrpeer.recovery import config as recovery
from sdrpeer.runtime import config as runtime
from sdrpeer.runtime.backoff import RestartConfig

PARTS = {
    "gossip": gossip,
    "election": election,
    "recovery": recovery,
    "supervisor": runtime,
    "deploy": deploy,
    "agent": agent_timers,
    "api": api_config,
}
"""Each sub-config of the tree and the module that declares it (and its presets)."""
SDRPEER = Path(__file__).resolve().parent.parent / "sdrpeer"


def test_the_presets_are_the_names_the_configuration_takes() -> None:
    assert tuple(tuning.PRESETS) == PRESET_NAMES


def test_the_tree_has_one_sub_config_per_part() -> None:
    fields = [f.name for f in dataclasses.fields(tuning.Tuning)]
    assert fields == ["name", *PARTS]


@pytest.mark.parametrize("name", list(tuning.PRESETS))
def test_a_preset_is_every_parts_preset_of_the_same_name(name: str) -> None:
    tree = tuning.preset(name)
    assert tree.name == name
    for part, module in PARTS.items():
        assert getattr(tree, part) == getattr(module, name)(), part


def test_fast_test_is_faster_where_loopback_allows() -> None:
    lan, fast = tuning.lan(), tuning.fast_test()
    assert (fast.gossip.probe_interval, lan.gossip.probe_interval) == (0.1, 0.15)
    assert (fast.election.grace, lan.election.grace) == (0.25, 1.0)
    assert (fast.election.startup_grace, lan.election.startup_grace) == (0.75, 1.5)
    assert (fast.election.rejoin_grace, lan.election.rejoin_grace) == (1.5, 6.0)
    assert (fast.recovery.settle_s, lan.recovery.settle_s) == (1.0, 10.0)
    assert (fast.supervisor.hello_timeout, lan.supervisor.hello_timeout) == (5.0, 15.0)
    assert fast.supervisor.restart.maximum < lan.supervisor.restart.maximum
    # the same where nothing on loopback is quicker
    assert fast.deploy == lan.deploy
    assert fast.agent == lan.agent
    assert fast.api == lan.api


@pytest.mark.parametrize(("n", "lab_at_least"), [(5, 1.9), (20, 2.5)])
def test_the_lab_preset_suspects_a_silent_robot_only_after_seconds(
    n: int, lab_at_least: float
) -> None:
    """What a stalled process trips (a suspicion timing out unrefuted, a hung host's silence)
    lasts longer in `lab` than in `lan`, and far longer than in `fast_test`."""

    def min_suspicion(tree: tuning.Tuning) -> float:
        g = tree.gossip
        return suspicion_min_timeout(g.suspicion_mult, n, g.probe_interval)

    lab, lan, fast = tuning.lab(), tuning.lan(), tuning.fast_test()
    assert min_suspicion(lab) >= lab_at_least
    assert min_suspicion(lab) > 3 * min_suspicion(lan) > 3 * min_suspicion(fast)
    assert lab.gossip.probe_timeout > 3 * lan.gossip.probe_timeout
    assert lab.supervisor.heartbeat_timeout > lan.supervisor.heartbeat_timeout
    assert lab.election.grace > lan.election.grace
    # what no stall trips is lan's
    assert (lab.recovery, lab.deploy, lab.agent, lab.api) == (
        lan.recovery,
        lan.deploy,
        lan.agent,
        lan.api,
    )
    assert lab.gossip.with_(probe_interval=0.15, probe_timeout=0.075, suspicion_mult=3.2) == (
        lan.gossip
    )


@pytest.mark.parametrize("name", list(tuning.PRESETS))
def test_each_preset_is_said_in_one_line_where_the_help_lists_it(name: str) -> None:
    doc = tuning.PRESETS[name].__doc__ or ""
    assert doc.splitlines()[0] == PRESETS_SAID[name][0].upper() + PRESETS_SAID[name][1:] + "."
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    lab = next(a for a in sub.choices["lab"]._actions if isinstance(a, argparse._SubParsersAction))
    for command in (sub.choices["agent"], lab.choices["up"]):
        assert f"  {name:<10} {PRESETS_SAID[name]}\n" in command.format_help()


def test_lab_up_defaults_to_the_lab_preset() -> None:
    assert build_parser().parse_args(["lab", "up"]).preset == LAB_PRESET == "lab"
    assert UpOptions(robots=1, lab_dir=Path("lab")).preset == LAB_PRESET


def test_an_unknown_preset_names_the_known_ones() -> None:
    with pytest.raises(ValueError, match=r"unknown preset 'wan' \(known: lan, fast_test, lab\)"):
        tuning.preset("wan")


def _config_classes() -> list[type[Any]]:
    classes: list[type[Any]] = [tuning.Tuning, RestartConfig]
    for f in dataclasses.fields(tuning.Tuning):
        if f.name != "name":
            classes.append(type(getattr(tuning.lan(), f.name)))
    return classes


@pytest.mark.parametrize("cls", _config_classes(), ids=lambda c: c.__name__)
def test_every_knob_is_documented_where_it_is_declared(cls: type[Any]) -> None:
    tree = ast.parse(inspect.getsource(cls))
    body = tree.body[0]
    assert isinstance(body, ast.ClassDef)
    documented = set()
    for field, after in zip(body.body, [*body.body[1:], None], strict=True):
        if (
            isinstance(field, ast.AnnAssign)
            and isinstance(field.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            documented.add(field.target.id)
    assert {f.name for f in dataclasses.fields(cls)} <= documented


@pytest.mark.parametrize("cls", _config_classes(), ids=lambda c: c.__name__)
def test_every_knob_is_read_outside_its_declaration(cls: type[Any]) -> None:
    declared_in = Path(inspect.getfile(cls)).resolve()
    code = "\n".join(
        p.read_text() for p in sorted(SDRPEER.rglob("*.py")) if p.resolve() != declared_in
    )
    dead = [
        f.name for f in dataclasses.fields(cls) if not re.search(rf"\.{f.name}\b|\b{f.name}=", code)
    ]
    assert dead == []


def test_the_command_line_offers_every_preset() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    add_agent_parser(sub)
    agent_help = sub.choices["agent"].format_help()
    lab = build_parser()
    for name in tuning.PRESETS:
        assert name in agent_help
        assert lab.parse_args(["lab", "up", "--preset", name]).preset == name


def _flags(*argv: str) -> dict[str, Any]:
    parser = argparse.ArgumentParser()
    add_agent_parser(parser.add_subparsers(dest="command"))
    return agent_flag_values(parser.parse_args(["agent", *argv]))


@pytest.mark.parametrize("name", list(tuning.PRESETS))
async def test_the_preset_flag_reaches_every_part_of_an_agent(tmp_path: Path, name: str) -> None:
    flags = _flags(
        *("--name", "robot-1", "--insecure", "--preset", name, "--data-dir", str(tmp_path)),
        *("--bind", "127.0.0.1:0", "--api", "127.0.0.1:0"),
    )
    agent = Agent(build_config(None, flags))
    await agent.start()
    try:
        tree = tuning.preset(name)
        assert agent.tuning == tree
        assert agent.core is not None
        assert agent.core.config == tree.gossip
        assert agent.shell is not None
        assert agent.shell.codec.max_datagram == tree.gossip.datagram_limit
        assert agent.publisher.min_gap == tree.agent.record_gap
        assert agent.instances is not None
        assert agent.instances.config == tree.supervisor.with_(data_host="127.0.0.1")
        coordinator = agent.coordinator
        assert coordinator is not None
        assert coordinator.config == tree.deploy
        assert coordinator.election.config == tree.election
        assert coordinator.health.config == tree.recovery
        assert coordinator.local.config == tree.recovery
        assert agent.api_site is not None
        assert agent.api_site.table.limits == tree.api
    finally:
        await agent.stop(leave=False)
