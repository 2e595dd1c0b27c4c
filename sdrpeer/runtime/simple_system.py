"""A minimal system file for `sdrpeer run`: components and connections, all on one robot.

How it works: the YAML is composed with `YamlFile`, so every error says `file:line: field 'x':`.
Format (a stopgap until the full system file with requirements and standbys replaces it):

    components:
      - {name: Cam, target: pkg.mod:Camera, launcher: python, params: {fps: 10}}
      - {name: View, target: pkg.mod:Viewer}
    connections:
      - {from: Cam.image, to: View.image, policy: {buffer: 4}}

Each component becomes one instance of the same name; each connection a `ConnectionSpec` of its
sender (id `Cam.image->View.image`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from sdrpeer.monitor.yamlfile import YamlFile
from sdrpeer.runtime.spec import InstanceSpec, SpecError, default_conn_id

_COMPONENT_KEYS = ("name", "target", "launcher", "params")


def load_simple_system(path: Path | str) -> list[InstanceSpec]:
    """Read a minimal system file into instance specs (ConfigError naming file:line on error)."""
    return parse_simple_system(YamlFile.read(path))


def parse_simple_system(f: YamlFile) -> list[InstanceSpec]:
    """The instance specs of an already composed system file."""
    top = f.mapping(f.root, None, ("components", "connections"), ("components",))
    docs: dict[str, dict[str, Any]] = {}
    nodes: dict[str, yaml.Node] = {}
    for i, node in enumerate(f.sequence(top["components"], "components")):
        where = f"components[{i}]"
        fields = f.mapping(
            node, where, ("name", "target", "launcher", "params"), ("name", "target")
        )
        doc = {key: f.value(value) for key, value in fields.items()}
        name = doc["name"]
        if name in docs:
            f.fail(fields["name"], f"{where}.name", f"{name!r} given twice")
        _check(f, fields, where, doc)
        docs[str(name)] = {**doc, "connections": []}
        nodes[str(name)] = node
    conns = f.sequence(top["connections"], "connections") if "connections" in top else []
    for i, node in enumerate(conns):
        where = f"connections[{i}]"
        fields = f.mapping(node, where, ("from", "to", "policy"), ("from", "to"))
        sender, out_port = _endpoint(f, fields["from"], f"{where}.from", docs)
        receiver, in_port = _endpoint(f, fields["to"], f"{where}.to", docs)
        conn: dict[str, Any] = {
            "id": default_conn_id(sender, out_port, receiver, in_port),
            "out": out_port,
            "to": receiver,
            "in": in_port,
        }
        if "policy" in fields:
            conn["policy"] = f.value(fields["policy"])
        docs[sender]["connections"].append(conn)
        try:
            InstanceSpec.from_json(docs[sender], where)
        except SpecError as e:
            field = re.sub(r"^(connections\[\d+\])\.connections\[\d+\]", r"\1", e.field)
            f.fail(fields.get("policy", node), field, _message(e))
    return [InstanceSpec.from_json(doc, name) for name, doc in docs.items()]


def _check(f: YamlFile, fields: dict[str, yaml.Node], where: str, doc: dict[str, Any]) -> None:
    try:
        InstanceSpec.from_json(doc, where)
    except SpecError as e:
        key = e.field.rsplit(".", 1)[-1]
        node = fields.get(key) or next(iter(fields.values()))
        f.fail(node, e.field, _message(e))


def _endpoint(
    f: YamlFile, node: yaml.Node, where: str, docs: dict[str, dict[str, Any]]
) -> tuple[str, str]:
    text = f.value(node)
    comp, dot, port = str(text).rpartition(".")
    if not isinstance(text, str) or not dot or not comp or not port:
        f.fail(node, where, f"expected Component.port, got {text!r}")
    if comp not in docs:
        f.fail(node, where, f"no component {comp!r} (known: {', '.join(docs) or 'none'})")
    return comp, port


def _message(e: SpecError) -> str:
    return str(e).split("': ", 1)[-1]
