"""YAML files whose every value keeps its line, so errors can say `file:line: field 'x': ...`.

How it works: the text is *composed* (not loaded) into yaml nodes, which carry their start marks.
Callers walk the nodes with `mapping()` (checks keys: unknown and missing ones are errors) and
turn a node into a Python value with `parse(node, field, parser)`, which wraps the parser's
`ValueError` into the file's error type with the node's line and the field's dotted name.

Hostile files are refused before they cost anything: at most `MAX_BYTES` of text, `MAX_DEPTH`
levels of nesting, `MAX_NODES` nodes once every alias is expanded (an alias bomb of a few lines
would otherwise become gigabytes when walked), no recursive alias, no tag outside YAML's plain
types (`!!python/object` ...), no control character. Each is a `file:line` error, never a
traceback. Every YAML file the project reads (system, robot, scenario, profile, agent config) is
composed by `compose()`.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any, NoReturn, TypeVar

import yaml

from sdrpeer.errors import ConfigError

T = TypeVar("T")


MAX_BYTES = 1_000_000
"""Largest YAML file read (a system file of a hundred components is about 20 kB)."""
MAX_DEPTH = 64
"""Deepest nesting of lists and mappings."""
MAX_NODES = 200_000
"""Most nodes a document may hold with every alias expanded."""
MERGE_TAG = "tag:yaml.org,2002:merge"
PLAIN_TAGS = frozenset(
    f"tag:yaml.org,2002:{t}"
    for t in ("null", "bool", "int", "float", "str", "seq", "map", "timestamp", "binary", "merge")
)
"""The tags a file may carry (what a plain YAML value resolves to, and merge keys)."""


def line_of(node: yaml.Node) -> int:
    """1-based line where a node starts."""
    return int(node.start_mark.line) + 1


class _Refused(yaml.MarkedYAMLError):
    """A hostile document (too deep, too big once expanded, a recursive alias, a tag)."""


class _Composer(yaml.SafeLoader):
    """SafeLoader composing under the module's limits (depth, expanded size, tags)."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self._depth = 0
        self._sizes: dict[int, int] = {}  # id(node) -> its node count with aliases expanded
        self._total = 0

    def compose_node(self, parent: yaml.Node | None, index: int) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()  # type: ignore[no-untyped-call]
            node = super().compose_node(parent, index)
            size = None if node is None else self._sizes.get(id(node))
            if size is None:
                raise _Refused(None, None, "an alias refers to its own anchor", event.start_mark)
            self._count(size, event.start_mark)
            return node
        start = self.peek_event().start_mark  # type: ignore[no-untyped-call]
        self._depth += 1
        if self._depth > MAX_DEPTH:
            raise _Refused(None, None, f"nested deeper than {MAX_DEPTH} levels", start)
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if node is None:
            return None
        if node.tag not in PLAIN_TAGS:
            raise _Refused(None, None, f"tag {node.tag!r} is not allowed", node.start_mark)
        size = 1
        if isinstance(node, yaml.SequenceNode):
            size += sum(self._sizes[id(child)] for child in node.value)
        elif isinstance(node, yaml.MappingNode):
            size += sum(self._sizes[id(k)] + self._sizes[id(v)] for k, v in node.value)
        self._sizes[id(node)] = size
        self._count(1, start)
        return node

    def _count(self, size: int, mark: Any) -> None:
        self._total += size
        if self._total > MAX_NODES:
            raise _Refused(None, None, f"more than {MAX_NODES} values once aliases expand", mark)


def yaml_problem(name: str, e: yaml.MarkedYAMLError) -> str:
    """`name:line: not valid YAML: what` for a composer's or constructor's error."""
    mark = e.problem_mark or e.context_mark
    line = f":{mark.line + 1}" if mark is not None else ""
    return f"{name}{line}: not valid YAML: {e.problem or e.context}"


def compose(text: str, name: str, error: type[ConfigError] = ConfigError) -> tuple[Any, Any]:
    """(loader, root node or None) of one YAML document, under the module's limits; every
    problem is `error("name:line: not valid YAML: ...")`. Construct values with
    `loader.construct_object(node, deep=True)` (see `YamlFile.value`)."""
    if len(text) > MAX_BYTES:
        raise error(f"{name}: not valid YAML: larger than {MAX_BYTES} bytes")
    try:
        loader = _Composer(text)
        return loader, loader.get_single_node()
    except yaml.MarkedYAMLError as e:
        raise error(yaml_problem(name, e)) from None
    except yaml.reader.ReaderError as e:
        at = text.count("\n", 0, max(0, e.position)) + 1
        raise error(
            f"{name}:{at}: not valid YAML: character {e.character!r} is not allowed"
        ) from None
    except yaml.YAMLError as e:
        raise error(f"{name}: not valid YAML: {e}") from None
    except RecursionError:
        raise error(f"{name}: not valid YAML: nested too deeply") from None


def read_text(path: Path | str, error: type[ConfigError] = ConfigError) -> str:
    """A YAML file's text (UTF-8, at most `MAX_BYTES`); an unreadable file names itself."""
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_BYTES + 1)
        if len(data) > MAX_BYTES:
            raise error(f"{path}: not valid YAML: larger than {MAX_BYTES} bytes")
        return data.decode("utf-8")
    except OSError as e:
        raise error(f"{path}: cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise error(f"{path}: cannot read: not UTF-8 text (byte {e.start})") from None


class YamlFile:
    """One composed YAML document and the name used in its error messages."""

    def __init__(self, text: str, name: str, error: type[ConfigError] = ConfigError) -> None:
        self.name = name
        self.error = error
        self._loader, self.root = compose(text, name, error)

    @classmethod
    def read(cls, path: Path | str, error: type[ConfigError] = ConfigError) -> YamlFile:
        """Read and compose a file; an unreadable file is an error naming it."""
        return cls(read_text(path, error), str(path), error)

    def fail(self, node: yaml.Node | None, field: str | None, message: str) -> NoReturn:
        """Raise the file's error at a node's line, naming the field."""
        where = self.name if node is None else f"{self.name}:{line_of(node)}"
        what = "" if field is None else f" field '{field}':"
        raise self.error(f"{where}:{what} {message}")

    def value(self, node: yaml.Node) -> Any:
        """The plain Python value of a node (scalars, lists and dicts as yaml.safe_load gives)."""
        try:
            return self._loader.construct_object(node, deep=True)
        except yaml.MarkedYAMLError as e:  # e.g. an unhashable mapping key
            self.fail(node, None, f"not valid YAML: {e.problem or e.context}")

    def parse(self, node: yaml.Node, field: str, parser: Callable[[Any], T]) -> T:
        """parser(value of node), with its ValueError reported at the node's line."""
        try:
            return parser(self.value(node))
        except (ValueError, TypeError) as e:
            self.fail(node, field, str(e))

    def pairs(self, node: yaml.MappingNode, field: str | None) -> list[tuple[Any, Any]]:
        """The (key node, value node) pairs of a mapping with its merge keys (`<<: *base`)
        merged in as YAML says: the mapping's own keys win, then the first merged one."""
        own = [(k, v) for k, v in node.value if k.tag != MERGE_TAG]
        if len(own) == len(node.value):
            return list(node.value)
        try:
            self._loader.flatten_mapping(node)  # node.value: the merged pairs, then its own
        except yaml.MarkedYAMLError as e:
            self.fail(node, field, f"not valid YAML: {e.problem or e.context}")
        merged = node.value[: len(node.value) - len(own)]
        taken = {k.value for k, _ in own if isinstance(k, yaml.ScalarNode)}
        out = []
        for k, v in merged:
            key = k.value if isinstance(k, yaml.ScalarNode) else None
            if key is None or key not in taken:
                out.append((k, v))
                taken.add(key)
        node.value = out + own
        return list(node.value)

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
        for key_node, value_node in self.pairs(node, field):
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
