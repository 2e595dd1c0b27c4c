"""Load a system file (YAML, RTSProfile-like) into a validated `SystemDef`.

How it works: the text is composed with `YamlFile` (every node keeps its line) and walked once
through a `Problems` collector: the top level here, then `components:` (sdrpeer.system.components),
`composites:` (sdrpeer.system.composites: each becomes one component), `connections:`
(sdrpeer.system.connections, which needs the components' classes and profiles),
`allocation:`, `recovery:` and `compliance:` (sdrpeer.system.sections). A wrong field is
recorded and the walk goes on, so one `SystemFileError` lists every problem, sorted by line, each as
`file:line: field 'components[2].requires.memory': message`. Nothing is returned unless the
whole file is right. The format is documented in docs/system-file.md; the JSON Schema for editors
is `schema_path()`.

    version: 1
    name: paper-demo
    components:
      - {name: Cam, target: components.camera:Camera, profile: profiles/camera.yaml,
         requires: {memory: 520MB}, standby: {other_robots: 1}}
    connections:
      - {from: Cam.image, to: Detect.image, policy: {push: new}}
    allocation: {strategy: first_fit, constraints: {mem_free_above: 500MB}}
    recovery: {rules: [{cause: memory_shortage, when: mem_free <= 200MB, actions: [restart]}]}
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from sdrpeer.errors import SpecError, SystemFileError
from sdrpeer.runtime.spec import _name
from sdrpeer.system.components import read_components
from sdrpeer.system.composites import read_composites
from sdrpeer.system.connections import read_connections
from sdrpeer.system.model import SystemDef
from sdrpeer.system.problems import MISSING, Problems
from sdrpeer.system.sections import (
    read_allocation,
    read_compliance,
    read_recovery,
    read_streams,
)
from sdrpeer.yamlfile import YamlFile

__all__ = ["SystemFileError", "load_system", "parse_system", "schema_path"]

TOP_KEYS = (
    "version",
    "name",
    "components",
    "composites",
    "connections",
    "allocation",
    "recovery",
    "streams",
    "compliance",
)
VERSIONS = (1,)
_LINE = re.compile(r"^.*?:(\d+):")


def schema_path() -> Path:
    """The JSON Schema (draft 2020-12) of system files, for editors and `sdrpeer system schema`."""
    return Path(__file__).with_name("schema.json")


def load_system(path: Path | str) -> SystemDef:
    """Read and validate a system file; the paths it names (profiles, `script` files, `exec`
    programs) are relative to its directory (sdrpeer.system.paths)."""
    f = YamlFile.read(path, SystemFileError)
    return _build(f, Path(path).parent)


def parse_system(text: str, name: str, *, base_dir: Path | str | None = None) -> SystemDef:
    """Validate system-file text; `name` is used in messages (and its directory, unless
    `base_dir` is given, is where relative paths start)."""
    f = YamlFile(text, name, SystemFileError)
    return _build(f, Path(base_dir) if base_dir is not None else Path(name).parent)


def _build(f: YamlFile, base_dir: Path) -> SystemDef:
    p = Problems(f)
    top = p.mapping(f.root, None, TOP_KEYS, ("name", "components")) or {}
    p.get(top, "version", "", _version, 1)
    name = _system_name(p, top)
    components = read_components(p, top["components"], base_dir) if "components" in top else {}
    composites, members = read_composites(p, top.get("composites"), base_dir, components)
    components.update(composites)
    connections = read_connections(p, top.get("connections"), components, members)
    allocation = read_allocation(p, top.get("allocation"))
    recovery = read_recovery(p, top.get("recovery"))
    streams = read_streams(p, top.get("streams"))
    compliance = read_compliance(p, top.get("compliance"))
    if p.items:
        p.items.sort(key=_line)
        p.check()
    defs = tuple(c.definition for c in components.values() if c.definition is not None)
    return SystemDef(
        name=name,
        components=defs,
        connections=connections,
        allocation=allocation,
        recovery=recovery,
        streams=streams,
        compliance=compliance,
        source=f.name,
    )


def _version(value: object) -> int:
    if isinstance(value, bool) or value not in VERSIONS:
        known = ", ".join(str(v) for v in VERSIONS)
        raise ValueError(f"unsupported version {value!r} (this sdrpeer reads version {known})")
    return int(value)


def _system_name(p: Problems, top: dict[str, yaml.Node]) -> str:
    node = top.get("name")
    if node is None:
        return MISSING  # type: ignore[no-any-return]
    try:
        return _name(p.f.value(node), "name")
    except SpecError as e:
        p.add(node, "name", str(e).split("': ", 1)[-1])
        return MISSING  # type: ignore[no-any-return]


def _line(problem: str) -> int:
    """The line a problem is at (0 for problems about the whole file)."""
    match = _LINE.match(problem)
    return int(match.group(1)) if match else 0
