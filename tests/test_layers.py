"""The package structure: layers import only downwards, and no module imports itself in a circle.

How it works: every module of sdrpeer/ is parsed with `ast` (no import runs) and every
`import sdrpeer.x` / `from sdrpeer.x import y` is an edge, wherever it stands: at the top, inside a
function (a lazy import), or under `if TYPE_CHECKING` (a type-only dependency is a dependency of
the design all the same). A unit is a package (`sdrpeer/gossip/`) or a top-level module
(`sdrpeer/errors.py`). `LAYERS` lists the units from the bottom up; a unit may import its own
modules and any unit of a lower layer, never one of its own layer or above. A new package must be
placed in a layer here before it can be imported.
"""

from __future__ import annotations

import ast
import functools
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "sdrpeer"

LAYERS: list[tuple[str, set[str]]] = [
    ("the package and its errors", {"__init__", "errors"}),
    ("foundation", {"units", "yamlfile", "vocabulary", "eventlog"}),
    ("plugins", {"plugins"}),
    ("primitives", {"keys", "launch", "control", "sdk", "client", "netlab"}),
    ("codecs and transports", {"record", "gossip", "dataplane"}),
    ("processes and settings", {"config", "runtime", "host"}),
    ("hosts of other middleware's components", {"ros2", "openrtm"}),
    ("system model", {"system"}),
    ("plans and elections", {"plan", "election"}),
    ("allocation", {"alloc"}),
    ("recovery", {"recovery"}),
    ("monitoring and the API", {"monitor", "api"}),
    ("deployment, dashboard, profiling, port tools", {"deploy", "dashboard", "profiling", "ports"}),
    ("the agent", {"agent"}),
    ("the lab and the simulator", {"lab", "sim"}),
    ("experiments on a lab", {"chaos", "demo"}),
    ("the command line", {"cli"}),
    ("entry point", {"__main__"}),
]


MAX_TOP_LEVEL_MODULES = 10


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__" and len(parts) > 1:
        parts.pop()
    return ".".join(parts)


@functools.cache
def _imports() -> dict[str, set[str]]:
    """Module -> the sdrpeer modules it imports (a `from pkg import mod` counts as `pkg.mod`
    when that is a module, else as `pkg`)."""
    modules = {_module_name(p): p for p in ROOT.rglob("*.py")}
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in modules.items():
        graph[name]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [
                    f"{node.module}.{a.name}"
                    if f"{node.module}.{a.name}" in modules
                    else node.module
                    for a in node.names
                ]
            for imported in targets:
                target = imported
                while target not in modules and "." in target:
                    target = target.rpartition(".")[0]
                if target.split(".")[0] == "sdrpeer" and target in modules and target != name:
                    graph[name].add(target)
    return graph


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _layer_of() -> dict[str, int]:
    out: dict[str, int] = {}
    for i, (_, units) in enumerate(LAYERS):
        for unit in units:
            out[unit] = i
    return out


def _circles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[set[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = set()
                while True:
                    top = stack.pop()
                    on_stack.discard(top)
                    component.add(top)
                    if top == node:
                        break
                if len(component) > 1:
                    found.append(component)
    return found


def test_every_unit_has_a_layer() -> None:
    units = {_unit(m) for m in _imports()}
    placed = set(_layer_of())
    assert units - placed == set(), "place these in LAYERS"
    assert placed - units <= {"vocabulary"}, "LAYERS names units that do not exist"


def _upward(graph: dict[str, set[str]]) -> list[str]:
    """The imports of a unit of its own layer or a higher one, as sentences."""
    layer = _layer_of()
    return sorted(
        f"{module} ({LAYERS[layer[_unit(module)]][0]}) imports {target} "
        f"({LAYERS[layer[_unit(target)]][0]})"
        for module, targets in graph.items()
        for target in targets
        if _unit(module) != _unit(target) and layer[_unit(target)] >= layer[_unit(module)]
    )


def test_layers_import_only_downwards() -> None:
    assert _upward(_imports()) == []


def test_no_module_imports_itself_in_a_circle() -> None:
    assert _circles(_imports()) == []


def test_the_top_level_holds_few_modules() -> None:
    top = sorted(p.name for p in ROOT.glob("*.py"))
    assert len(top) <= MAX_TOP_LEVEL_MODULES, top


@pytest.mark.parametrize(
    ("graph", "expected"),
    [
        ({"a": {"b"}, "b": {"a"}, "c": set()}, [{"a", "b"}]),
        ({"a": {"b"}, "b": {"c"}, "c": {"a"}}, [{"a", "b", "c"}]),
        ({"a": {"b"}, "b": {"c"}, "c": set()}, []),
    ],
)
def test_the_circle_finder_finds_circles(
    graph: dict[str, set[str]], expected: list[set[str]]
) -> None:
    assert _circles(graph) == expected


def test_an_import_upwards_or_sideways_is_caught() -> None:
    """The check itself, on made-up graphs."""
    assert _upward({"sdrpeer.agent.agent": {"sdrpeer.gossip.core"}}) == []
    assert _upward({"sdrpeer.gossip.core": {"sdrpeer.gossip.table"}}) == []
    up = _upward({"sdrpeer.gossip.core": {"sdrpeer.agent.agent"}})
    assert up == [
        "sdrpeer.gossip.core (codecs and transports) imports sdrpeer.agent.agent (the agent)"
    ]
    assert len(_upward({"sdrpeer.deploy.routes": {"sdrpeer.dashboard.feed"}})) == 1  # same layer
