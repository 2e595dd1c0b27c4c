"""The JSON Schema for editors: valid draft 2020-12, accepts every example, matches the loader."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from sdrpeer.system.components import COMPONENT_KEYS, REQUIRES_KEYS, STANDBY_KEYS
from sdrpeer.system.composites import COMPOSITE_KEYS, MEMBER_KEYS
from sdrpeer.system.connections import CONNECTION_KEYS
from sdrpeer.system.loader import TOP_KEYS, load_system, schema_path
from sdrpeer.system.model import STANDBY_MODES
from sdrpeer.system.recovery_defaults import ACTIONS, CAUSES
from sdrpeer.system.sections import ALLOCATION_KEYS, RECOVERY_KEYS, RULE_KEYS, THRESHOLDS

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples").rglob("system*.yaml"))


def schema() -> dict[str, Any]:
    """The schema file as a dict."""
    doc: dict[str, Any] = json.loads(schema_path().read_text(encoding="utf-8"))
    return doc


def keys(node: dict[str, Any]) -> set[str]:
    """The property names an object schema allows."""
    return set(node["properties"])


def test_examples_exist() -> None:
    assert len(EXAMPLES) >= 2


def test_schema_keys_match_the_loader() -> None:
    s = schema()
    d = s["$defs"]
    assert s["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert keys(s) == set(TOP_KEYS)
    assert keys(d["component"]) == set(COMPONENT_KEYS)
    assert keys(d["requires"]) == set(REQUIRES_KEYS)
    assert keys(d["composite"]) == set(COMPOSITE_KEYS)
    assert keys(d["member"]) == set(MEMBER_KEYS)
    assert keys(d["standby"]) == set(STANDBY_KEYS)
    assert keys(d["connection"]) == set(CONNECTION_KEYS)
    assert keys(d["allocation"]) == set(ALLOCATION_KEYS)
    assert keys(d["allocation"]["properties"]["constraints"]) == set(THRESHOLDS)
    assert keys(d["recovery"]) == set(RECOVERY_KEYS)
    assert keys(d["rule"]) == set(RULE_KEYS)
    assert d["rule"]["properties"]["cause"]["enum"] == list(CAUSES)
    assert d["rule"]["properties"]["actions"]["items"]["enum"] == list(ACTIONS)
    assert d["standby"]["properties"]["mode"]["enum"] == list(STANDBY_MODES)
    objects = ("component", "composite", "member", "requires", "standby", "connection")
    for name in (*objects, "allocation", "rule"):
        assert d[name]["additionalProperties"] is False


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_validates(path: Path) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(schema())
    jsonschema.Draft202012Validator.check_schema(schema())
    errors = [e.message for e in validator.iter_errors(yaml.safe_load(path.read_text()))]
    assert errors == []
    load_system(path)  # and the loader agrees


@pytest.mark.parametrize(
    "doc",
    [
        {"name": "s"},
        {"name": "s", "components": [{"name": "C"}]},
        {
            "name": "s",
            "components": [{"name": "C", "target": "m:C", "requires": {"memory": "5XB"}}],
        },
        {"name": "s", "components": [{"name": "C", "target": "m:C"}], "colour": 1},
        {"name": "s", "components": [{"name": "C", "target": "m:C"}], "version": 2},
        {
            "name": "s",
            "components": [{"name": "C", "target": "m:C"}],
            "recovery": {"rules": [{"cause": "flood", "actions": ["restart"]}]},
        },
    ],
)
def test_schema_rejects_obvious_mistakes(doc: dict[str, Any]) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    assert list(jsonschema.Draft202012Validator(schema()).iter_errors(doc))
