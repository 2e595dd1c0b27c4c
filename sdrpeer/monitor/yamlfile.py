"""YAML files whose every value keeps its line, so errors can say `file:line: field 'x': ...`.

How it works: the text is *composed* (not loaded) into yaml nodes, which carry their start marks.
Callers walk the nodes with `mapping()` (checks keys: unknown and missing ones are errors) and
turn a node into a Python value with `parse(node, field, parser)`, which wraps the parser's
`ValueError` into the file's error type with the node's line and the field's dotted name.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any, NoReturn, TypeVar

import yaml

from sdrpeer.errors import ConfigError

T = TypeVar("T")


def line_of(node: yaml.Node) -> int:
    """1-based line where a node starts."""
    return int(node.start_mark.line) + 1


class YamlFile:
    """One composed YAML document and the name used in its error messages."""

    def __init__(self, text: str, name: str, error: type[ConfigError] = ConfigError) -> None:
        self.name = name
        self.error = error
        self._loader = yaml.SafeLoader(text)
        try:
            self.root: yaml.Node | None = self._loader.get_single_node()
        except yaml.MarkedYAMLError as e:
            mark = e.problem_mark or e.context_mark
            line = f":{mark.line + 1}" if mark is not None else ""
            raise error(f"{name}{line}: not valid YAML: {e.problem or e.context}") from None
        except yaml.YAMLError as e:
            raise error(f"{name}: not valid YAML: {e}") from None

    @classmethod
    def read(cls, path: Path | str, error: type[ConfigError] = ConfigError) -> YamlFile:
        """Read and compose a file; an unreadable file is an error naming it."""
        try:
            text = Path(path).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise error(f"{path}: cannot read: {getattr(e, 'strerror', None) or e}") from None
        return cls(text, str(path), error)

    def fail(self, node: yaml.Node | None, field: str | None, message: str) -> NoReturn:
        """Raise the file's error at a node's line, naming the field."""
        where = self.name if node is None else f"{self.name}:{line_of(node)}"
        what = "" if field is None else f" field '{field}':"
        raise self.error(f"{where}:{what} {message}")

    def value(self, node: yaml.Node) -> Any:
        """The plain Python value of a node (scalars, lists and dicts as yaml.safe_load gives)."""
        return self._loader.construct_object(node, deep=True)

    def parse(self, node: yaml.Node, field: str, parser: Callable[[Any], T]) -> T:
        """parser(value of node), with its ValueError reported at the node's line."""
        try:
            return parser(self.value(node))
        except (ValueError, TypeError) as e:
            self.fail(node, field, str(e))

    def mapping(
        self,
        node: yaml.Node | None,
        field: str | None,
        allowed: Collection[str],
        required: Collection[str] = (),
    ) -> dict[str, yaml.Node]:
        """Key -> value node of a mapping; unknown, repeated and missing keys are errors."""
        if not isinstance(node, yaml.MappingNode):
            self.fail(node, field, f"expected a mapping with {', '.join(allowed)}")
        prefix = "" if field is None else f"{field}."
        out: dict[str, yaml.Node] = {}
        for key_node, value_node in node.value:
            key = self.value(key_node)
            if not isinstance(key, str):
                self.fail(key_node, f"{prefix}{key}", "field names are strings")
            if key not in allowed:
                known = ", ".join(allowed)
                self.fail(key_node, f"{prefix}{key}", f"unknown field (known: {known})")
            if key in out:
                first = line_of(out[key])
                self.fail(key_node, f"{prefix}{key}", f"given twice (first at line {first})")
            out[key] = value_node
        for key in required:
            if key not in out:
                self.fail(node, f"{prefix}{key}", "missing (required)")
        return out

    def sequence(self, node: yaml.Node | None, field: str) -> list[yaml.Node]:
        """The item nodes of a YAML list."""
        if not isinstance(node, yaml.SequenceNode):
            self.fail(node, field, "expected a list")
        return list(node.value)
