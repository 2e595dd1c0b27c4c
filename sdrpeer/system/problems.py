"""Every problem of a system file, collected in one pass and raised together.

How it works: the loader walks the document through a `Problems`, which wraps a `YamlFile` whose
error type is `SystemFileError`. Each field is read inside `guard()` (or through `get`): when the
check fails, `YamlFile.fail` raises, the guard records the message (`file:line: field 'a.b': ...`)
and the walk goes on with the next field, so one run reports everything that is wrong. `check()`
at the end raises one `SystemFileError` whose message lists the problems one per line and whose
`.problems` holds them as a list. A field that failed yields `MISSING` (or the caller's default),
so later checks that need it are skipped rather than reported twice.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, NoReturn, TypeVar, cast

import yaml

from sdrpeer.errors import SystemFileError
from sdrpeer.yamlfile import YamlFile

T = TypeVar("T")


class _Missing:
    """The value of a field that was absent or wrong (falsy, so `if value:` skips it)."""

    def __bool__(self) -> bool:
        return False

    def __repr__(self) -> str:
        return "MISSING"


MISSING: Any = _Missing()
"""Returned for a field that failed its check (it has already been reported)."""


class Problems:
    """A composed system file plus the problems found in it so far."""

    def __init__(self, f: YamlFile) -> None:
        self.f = f
        self.items: list[str] = []

    @property
    def name(self) -> str:
        """The file's name as messages give it."""
        return self.f.name

    def fail(self, node: yaml.Node | None, field: str | None, message: str) -> NoReturn:
        """Stop reading the current field (recorded by the enclosing `guard`)."""
        self.f.fail(node, field, message)

    def add(self, node: yaml.Node | None, field: str | None, message: str) -> None:
        """Record a problem and go on."""
        with self.guard():
            self.f.fail(node, field, message)

    @contextmanager
    def guard(self) -> Iterator[None]:
        """Record a `SystemFileError` raised inside the block instead of propagating it."""
        try:
            yield
        except SystemFileError as e:
            self.items.extend(e.problems)

    def get(
        self,
        fields: dict[str, yaml.Node],
        key: str,
        where: str,
        parser: Callable[[Any], T],
        default: Any,
    ) -> T:
        """parser(value of `key`) if present, else `default`; a bad value is recorded: MISSING."""
        node = fields.get(key)
        if node is None:
            return cast(T, default)
        try:
            return self.f.parse(node, f"{where}.{key}" if where else key, parser)
        except SystemFileError as e:
            self.items.extend(e.problems)
            return cast(T, MISSING)

    def mapping(
        self,
        node: yaml.Node | None,
        field: str | None,
        allowed: Sequence[str] | None,
        required: Sequence[str] = (),
    ) -> dict[str, yaml.Node] | None:
        """`YamlFile.mapping` that records its problems and returns None instead of raising.

        Unknown keys are all reported (not only the first) and the known ones still returned,
        so their values are checked too. `allowed=None`: any string key (params, traffic).
        """
        if not isinstance(node, yaml.MappingNode):
            keys = "" if allowed is None else f" with {', '.join(allowed)}"
            self.add(node, field, f"expected a mapping{keys}")
            return None
        prefix = "" if field is None else f"{field}."
        out: dict[str, yaml.Node] = {}
        pairs: list[tuple[Any, Any]] = []
        with self.guard():  # a bad merge key is recorded
            pairs = self.f.pairs(node, field)
        for key_node, value_node in pairs:
            key = self.f.value(key_node)
            if not isinstance(key, str):
                self.add(key_node, f"{prefix}{key}", "field names are strings")
            elif allowed is not None and key not in allowed:
                known = ", ".join(allowed)
                self.add(key_node, f"{prefix}{key}", f"unknown field (known: {known})")
            elif key in out:
                first = out[key].start_mark.line + 1
                self.add(key_node, f"{prefix}{key}", f"given twice (first at line {first})")
            else:
                out[key] = value_node
        for key in required:
            if key not in out:
                self.add(node, f"{prefix}{key}", "missing (required)")
        return out

    def sequence(self, node: yaml.Node | None, field: str) -> list[yaml.Node]:
        """The items of a YAML list; anything else is recorded and gives no items."""
        if not isinstance(node, yaml.SequenceNode):
            self.add(node, field, "expected a list")
            return []
        return list(node.value)

    def check(self) -> None:
        """Raise every recorded problem as one SystemFileError (no-op when there is none)."""
        if self.items:
            raise SystemFileError.collect(self.name, self.items)
