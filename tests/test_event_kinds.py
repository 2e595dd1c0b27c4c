"""Event kinds are declared once (`sdrpeer.eventlog.EventKind`): producers and consumers name
its members. Parsed with `ast`: no string constant in sdrpeer/ spells a dotted kind outside
eventlog.py (docstrings aside), and no `events.add(ts, kind, ...)` or deploy `Log(kind, ...)`
passes its kind as a string."""

from __future__ import annotations

import ast
from pathlib import Path

from sdrpeer.eventlog import EventKind
from tests.sources import docstrings

ROOT = Path(__file__).resolve().parent.parent / "sdrpeer"

OTHER_MEANINGS = {
    "sdrpeer/record/robot.py": {"instance.state": "a record field's path in decode errors"},
}
"""Modules where a string equal to a kind means something else, with why."""


def _spelled(source: str, allowed: set[str] | None = None) -> list[str]:
    """`line: 'kind'` of every dotted kind spelled as a string (but `allowed`), and of every
    kind given to events.add or Log as a string constant."""
    tree = ast.parse(source)
    docs = docstrings(tree)
    dotted = {k.value for k in EventKind if "." in k.value} - (allowed or set())
    found = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in docs
            and node.value in dotted
        ):
            found.append(f"{node.lineno}: {node.value!r}")
        if isinstance(node, ast.Call):
            func = node.func
            kind = None
            if (
                isinstance(func, ast.Attribute)
                and func.attr == "add"
                and len(node.args) >= 2
                and "event" in ast.unparse(func.value)
            ):
                kind = node.args[1]
            elif isinstance(func, ast.Name) and func.id == "Log" and node.args:
                kind = node.args[0]
            if isinstance(kind, ast.Constant) and not (
                isinstance(kind.value, str) and kind.value in dotted
            ):
                found.append(f"{kind.lineno}: {kind.value!r} given as a string")
    return found


def test_no_module_spells_an_event_kind() -> None:
    found = [
        f"{path.relative_to(ROOT.parent)}:{hit}"
        for path in sorted(ROOT.rglob("*.py"))
        if path.name != "eventlog.py"
        for hit in _spelled(
            path.read_text(), set(OTHER_MEANINGS.get(str(path.relative_to(ROOT.parent)), {}))
        )
    ]
    assert found == [], "name these with sdrpeer.eventlog.EventKind"


def test_the_check_finds_spelled_kinds() -> None:
    assert _spelled('x = "member.dead"\n') == ["1: 'member.dead'"]
    assert _spelled('log.events.add(1.0, "trap", "r1")\n') == ["1: 'trap' given as a string"]
    assert _spelled('effects.append(Log("move", {}))\n') == ["1: 'move' given as a string"]
    assert _spelled('"""member.dead is a kind."""\nevents.add(1.0, EventKind.TRAP, "r1")\n') == []


def test_every_kind_is_documented_and_distinct() -> None:
    values = [k.value for k in EventKind]
    assert len(values) == len(set(values))
    source = (ROOT / "eventlog.py").read_text()
    tree = ast.parse(source)
    enum = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "EventKind")
    documented = {
        a.targets[0].id
        for a, b in zip(enum.body, enum.body[1:], strict=False)
        if isinstance(a, ast.Assign)
        and isinstance(a.targets[0], ast.Name)
        and isinstance(b, ast.Expr)
        and isinstance(b.value, ast.Constant)
    }
    assert {k.name for k in EventKind} == documented
