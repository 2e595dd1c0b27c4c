"""The client commands stay fast: what they import, and the benchmark that times them.

How it works: `python -X importtime` lists every module a process imports; the commands a user
runs to watch a fleet (`members`, `status`, `instances`, with --json) are run that way as real
subprocesses against a real agent, and must not load the agent, the web server, the allocator,
the system loader or the component SDK (each of these cost tens of milliseconds per call, the
whole of them most of a 1.3 s `status --json`). How fast they are is measured by
`tools/bench_cli.py`, which a test runs with a small N.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from sdrpeer.cli.instances import LAUNCHER_HELP
from sdrpeer.cli.main import GROUPS, _group_of, build_parser
from sdrpeer.runtime.spec import LAUNCHERS
from tests.realnet import RealCluster

ROOT = Path(__file__).resolve().parent.parent
WATCHING = ("members", "status", "instances")
NOT_FOR_A_CLIENT = (
    "aiohttp",
    "asyncio",
    "yaml",
    "psutil",
    "msgpack",
    "sdrpeer.agent",
    "sdrpeer.api",
    "sdrpeer.alloc",
    "sdrpeer.deploy",
    "sdrpeer.election",
    "sdrpeer.gossip",
    "sdrpeer.system",
    "sdrpeer.sdk",
    "sdrpeer.host",
    "sdrpeer.runtime",
    "sdrpeer.dashboard",
    "sdrpeer.profiling",
    "sdrpeer.demo",
    "sdrpeer.lab.up",
    "sdrpeer.netlab",
    "sdrpeer.record.robot",
)
"""Packages (and their modules) a watching command must not import."""
NOT_FOR_THE_PARSER = (
    "aiohttp",
    "asyncio",
    "yaml",
    "sdrpeer.agent",
    "sdrpeer.api",
    "sdrpeer.alloc",
    "sdrpeer.deploy",
    "sdrpeer.system",
    "sdrpeer.sdk",
    "sdrpeer.host",
    "sdrpeer.dashboard",
    "sdrpeer.profiling.measure",
    "sdrpeer.demo",
    "sdrpeer.lab.up",
)
"""What building the whole parser (`sdrpeer --help`) must not import: each command's code."""


def imported(argv: list[str]) -> tuple[set[str], str]:
    """(modules imported, stdout) of `python -X importtime -m sdrpeer ARGV` (it must exit 0)."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "sdrpeer", *argv],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=ROOT,
    )
    lines = done.stderr.splitlines()
    assert done.returncode == 0, "\n".join(ln for ln in lines if "import time:" not in ln)
    modules = {ln.rsplit("|", 1)[1].strip() for ln in lines if ln.startswith("import time:")}
    modules.discard("imported package")  # the header line's last column
    return modules, done.stdout


def forbidden(modules: set[str], packages: tuple[str, ...] = NOT_FOR_A_CLIENT) -> list[str]:
    """The modules of `modules` that belong to `packages`."""
    return sorted(m for m in modules if any(m == p or m.startswith(p + ".") for p in packages))


@pytest.mark.parametrize("command", [*WATCHING, "agent-info", "events"])
def test_the_parser_loads_no_command_it_does_not_run(command: str) -> None:
    modules, out = imported([command, "--help"])
    assert "--json" in out
    assert "sdrpeer.cli.main" in modules  # the measurement sees the command line itself
    assert forbidden(modules) == []


def test_the_whole_help_still_lists_every_command() -> None:
    modules, out = imported(["--help"])
    for names, _ in GROUPS:
        for command in names:
            assert f"    {command}" in out
    assert forbidden(modules, NOT_FOR_THE_PARSER) == []


def test_each_group_registers_its_commands_and_parses_as_the_whole_parser() -> None:
    whole = build_parser()
    for names, _ in GROUPS:
        only = build_parser(names[0])
        assert list(subcommands(only)) == list(names)
        for name in names:
            assert subcommands(only)[name].format_help() == subcommands(whole)[name].format_help()
    assert [n for names, _ in GROUPS for n in names] == list(subcommands(whole))
    assert _group_of(["status", "--json"]) == "status"
    assert _group_of(["--help"]) is None
    assert _group_of(["statsu"]) is None  # the whole parser says what the commands are


def test_the_launcher_help_names_every_built_in_launcher() -> None:
    instances = subcommands(build_parser("start-instance"))["start-instance"]
    assert all(name in LAUNCHER_HELP for name in LAUNCHERS)
    assert LAUNCHER_HELP in " ".join(instances.format_help().split())


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The parser's commands by name."""
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


@pytest.mark.realnet
def test_watching_a_fleet_loads_only_the_client(cluster: RealCluster) -> None:
    agent = cluster.start("robot-1")
    answers = {}
    for command in WATCHING:
        modules, out = imported([command, "--json", "--api", agent.api])
        answers[command] = json.loads(out)
        assert forbidden(modules) == [], command
    assert [m["name"] for m in answers["members"]] == ["robot-1"]
    assert set(answers["status"]) >= {"allocator", "plan", "components"}
    assert answers["instances"] == []
    members, _ = imported(["members", "--api", agent.api])  # the table, not JSON
    assert forbidden(members) == []


@pytest.mark.realnet
def test_the_cli_benchmark_runs_and_writes_its_figures(tmp_path: Path) -> None:
    out = tmp_path / "cli.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "bench_cli.py"),
            *("--robots", "2", "--n", "2", "--no-deploy", "--json", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "target: p50 <= 0.2 s wall for members|status|instances --json:" in done.stdout
    doc = json.loads(out.read_text())
    assert doc["robots"] == 2
    assert doc["preset"] == "lab"
    assert set(doc["commands"]) == {"python -c pass", *WATCHING}
    for name, row in doc["commands"].items():
        assert row["n"] == 2, name
        assert 0 < row["wall"]["p50_s"] <= row["wall"]["p95_s"], name
        assert row["cpu"]["p50_s"] > 0, name
    for name in WATCHING:
        assert doc["commands"][name]["request"]["p50_s"] > 0, name
    assert doc["missed"] == [c for c in WATCHING if doc["commands"][c]["wall"]["p50_s"] > 0.2]
