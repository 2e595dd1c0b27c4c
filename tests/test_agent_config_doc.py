"""docs/agent-config.md stays true: it lists every field of `AgentConfig` with its flag, every
flag of `sdrpeer agent` is one field, and `--config FILE` gives the same fields (the discover
switch both ways)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from sdrpeer.cli.agent import add_agent_parser, agent_flag_values
from sdrpeer.config import FIELDS, build_config, load_agent_config

DOC = Path(__file__).resolve().parent.parent / "docs" / "agent-config.md"
ROW = re.compile(r"^\| `(?P<field>[a-z0-9_]+)` \| (?P<flags>[^|]+) \|", re.MULTILINE)
NOT_FIELDS = {"help", "config", "command"}


def agent_parser() -> tuple[argparse.ArgumentParser, argparse.ArgumentParser]:
    top = argparse.ArgumentParser(prog="sdrpeer")
    sub = top.add_subparsers(dest="command")
    add_agent_parser(sub)
    return top, sub.choices["agent"]


def test_the_doc_lists_every_field_with_its_flags() -> None:
    _, parser = agent_parser()
    options = {a.dest: set(a.option_strings) for a in parser._actions}
    rows = {m["field"]: m["flags"] for m in ROW.finditer(DOC.read_text())}
    assert set(rows) == set(FIELDS), "docs/agent-config.md must list exactly the fields"
    for field, flags in rows.items():
        named = set(re.findall(r"`(--[a-z0-9-]+)`", flags))
        assert named, f"{field}: no flag in the doc's row"
        assert named <= options[field], (
            f"{field}: the doc names {named}, the parser {options[field]}"
        )


def test_every_flag_is_one_field_and_every_field_a_flag() -> None:
    _, parser = agent_parser()
    dests = {a.dest for a in parser._actions} - NOT_FIELDS
    assert dests == set(FIELDS)


def test_a_config_file_sets_what_the_flags_set_and_flags_win(tmp_path: Path) -> None:
    key = tmp_path / "cluster.key"
    key.write_text("00" * 32 + "\n")
    config = tmp_path / "agent.yaml"
    config.write_text("name: rover-3\nkey-file: cluster.key\ndiscover: true\nbind: 0.0.0.0:7946\n")
    top, _ = agent_parser()
    from_file = build_config(
        load_agent_config(config), agent_flag_values(top.parse_args(["agent"]))
    )
    assert from_file.discover is True
    assert from_file.key_file == key
    assert from_file.join == ()
    args = top.parse_args(["agent", "--no-discover", "--name", "rover-4"])
    flagged = build_config(load_agent_config(config), agent_flag_values(args))
    assert (flagged.discover, flagged.name) == (False, "rover-4")
    assert build_config(None, {"name": "r", "insecure": True}).discover is False  # off by default
