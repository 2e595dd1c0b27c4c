"""One vocabulary: no module but sdrpeer.vocabulary and the codecs spells a state or role word.

The rule the test enforces, module by module (parsed with `ast`, nothing imported):

- A *word* is a string constant equal, ignoring case, to the value of a member of
  `LifecycleState`, `ProcessState`, `InstanceRole` or `MemberState` ("active", "ACTIVE",
  "Standby", "left", ...). f-string pieces count only when a piece is exactly a word.
- Allowed where it is not a value of those concepts:
  * docstrings (module, class, function, and attribute docstrings);
  * field names: a key of a dict literal that has at most one word among its keys (a dict
    keyed by two or more words is a table of the states, `{"alive": GREEN, "dead": RED}`, and
    its keys are found), a subscript index (`doc["error"]`), the first argument of
    `.get`/`.pop`/`.setdefault`, the left side of `in`/`not in` (`"error" in body`). A JSON
    field called "error" or "created" is a field, not the ERROR or CREATED state;
  * `OTHER_MEANINGS`: a module where a word means something else, named with its reason (the
    lifecycle *event* "error", a log level, an election trigger, a recovery action...). This is
    the judgement call: "error" as the lifecycle event or a fault effect is another concept
    than the ERROR state; "left" as the reason an allocator steps down is not MemberState.LEFT.
- Allowed everywhere in `CODECS`: the modules that translate between a word and its wire
  spelling (and the vocabulary itself); and in `PENDING`, modules another branch is rewriting,
  until they are converted.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

from sdrpeer.vocabulary import InstanceRole, LifecycleState, MemberState, ProcessState
from tests.sources import docstrings

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "sdrpeer"
WORDS = frozenset(
    m.value.lower()
    for enum in (LifecycleState, ProcessState, InstanceRole, MemberState)
    for m in enum
)

CODECS = {
    "sdrpeer/vocabulary.py": "the words themselves",
    "sdrpeer/record/robot.py": "instance states and roles in gossip records and their JSON",
    "sdrpeer/gossip/wire.py": "member states as small ints in packets",
    "sdrpeer/runtime/spec.py": "a spec's `desired` in spec files and the API",
}
"""Modules that may spell the words (path relative to the repository)."""

PENDING: dict[str, str] = {}
"""Modules not converted yet: allowed while they still spell a word, found once they do not."""

OTHER_MEANINGS: dict[str, dict[str, str]] = {
    "sdrpeer/sdk/lifecycle.py": {"error": "the lifecycle event that leads to ERROR"},
    "sdrpeer/sdk/runner.py": {"error": "the lifecycle event that leads to ERROR"},
    "sdrpeer/sdk/faults.py": {"error": "the fault effect (FaultEffect.ERROR)"},
    "sdrpeer/config.py": {"error": "a log level"},
    "sdrpeer/dashboard/chromium.py": {"error": "a browser console message type"},
    "sdrpeer/election/core.py": {"left": "why an allocator steps down (an election trigger)"},
    "sdrpeer/election/rules.py": {"left": "an election trigger"},
    "sdrpeer/recovery/plugins.py": {"standby": "the recovery action 'promote a standby'"},
    "sdrpeer/system/components.py": {"standby": "the `standby:` block of a system file"},
    "sdrpeer/system/composites.py": {"standby": "the `standby:` block of a composite"},
    "sdrpeer/lab/procs.py": {"stopped": "what `lab down` says of an agent process"},
    "sdrpeer/cli/lab.py": {"stopped": "what `lab status` says of an agent process"},
}
"""Module -> word -> why the word is not the state or role there."""

_KEY_METHODS = frozenset({"get", "pop", "setdefault"})


def _field_names(tree: ast.AST) -> set[int]:
    """ids of the string constants used as the name of a field, not as a value."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            keys = [k for k in node.keys if isinstance(k, ast.Constant)]
            if sum(isinstance(k.value, str) and k.value.lower() in WORDS for k in keys) <= 1:
                out.update(id(k) for k in keys)
        elif isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
            out.add(id(node.slice))
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in _KEY_METHODS
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            out.add(id(node.args[0]))
        elif (
            isinstance(node, ast.Compare)
            and isinstance(node.left, ast.Constant)
            and isinstance(node.ops[0], ast.In | ast.NotIn)
        ):
            out.add(id(node.left))
    return out


def spelled_words(path: Path) -> Iterator[tuple[int, str]]:
    """(line, constant) for every word spelled in `path` outside docstrings and field names."""
    tree = ast.parse(path.read_text(), str(path))
    skip = docstrings(tree) | _field_names(tree)
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and node.value.lower() in WORDS
            and id(node) not in skip
        ):
            yield node.lineno, node.value


def offences(root: Path = PACKAGE) -> list[str]:
    """file:line: word, for every word spelled where the rule does not allow it."""
    found = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel in CODECS or rel in PENDING:
            continue
        other = OTHER_MEANINGS.get(rel, {})
        for line, word in spelled_words(path):
            if word.lower() not in other:
                found.append(f"{rel}:{line}: {word!r}")
    return found


def test_words_are_spelled_only_in_the_vocabulary_and_the_codecs() -> None:
    """Every state or role word outside the allow-lists is a finding."""
    found = offences()
    assert not found, "spell these with sdrpeer.vocabulary:\n" + "\n".join(found)


def test_allow_lists_name_existing_modules() -> None:
    """A module renamed or removed must leave the allow-lists too."""
    for rel in (*CODECS, *PENDING, *OTHER_MEANINGS):
        assert (ROOT / rel).is_file(), rel


def test_exceptions_are_still_needed() -> None:
    """An `OTHER_MEANINGS` word its module no longer spells, or a `PENDING` module converted,
    leaves its list (the lists stay as short as the code allows)."""
    stale = [rel for rel in PENDING if not list(spelled_words(ROOT / rel))]
    for rel, words in OTHER_MEANINGS.items():
        spelled = {w.lower() for _, w in spelled_words(ROOT / rel)}
        stale.extend(f"{rel}: {w}" for w in words if w not in spelled)
    assert not stale, "remove from the allow-lists:\n" + "\n".join(stale)


def test_the_rule_tells_fields_from_values(tmp_path: Path) -> None:
    """Field names and docstrings pass; values, in any case, are found."""
    src = tmp_path / "m.py"
    src.write_text(
        '"""Active."""\n'
        'x = {"error": 1, "ok": False}\n'
        'c = {"alive": 1, "Dead": 2}\n'
        'y = doc["created"]\n'
        'z = doc.get("left")\n'
        'w = "error" in doc\n'
        'a = state == "active"\n'
        'b = ("Standby", "SUSPECT")\n'
    )
    found = sorted(w for _, w in spelled_words(src))
    assert found == ["Dead", "SUSPECT", "Standby", "active", "alive"]


def test_words_are_unique_across_the_vocabulary() -> None:
    """A word belongs to one concept, except the role and the state it names (active)."""
    lifecycle = {m.value.lower() for m in LifecycleState}
    process = {m.value.lower() for m in ProcessState}
    members = {m.value for m in MemberState}
    assert not lifecycle & process
    assert not (lifecycle | process) & members
