"""Instance specs: validation naming the field, defaults, JSON round trips."""

from __future__ import annotations

from typing import Any

import pytest

from sdrpeer.errors import SpecError
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.vocabulary import LifecycleState

FULL: dict[str, Any] = {
    "name": "Cam1",
    "component": "CameraRTC",
    "launcher": "python",
    "target": "components.camera:CameraRTC",
    "params": {"fps": 10},
    "desired": "active",
    "role": "standby",
    "connections": [
        {"id": "c1", "out": "image", "to": "View1", "in": "image", "policy": {"buffer": 4}},
        {"out": "image", "to": "Far", "in": "image", "to_addr": "tcp://10.0.0.2:7000"},
    ],
}


def test_round_trip():
    s = InstanceSpec.from_json(FULL)
    assert InstanceSpec.from_json(s.to_json()) == s
    assert s.role == "standby"
    assert not s.wants_active()
    assert s.connections[1].id == "Cam1.image->Far.image"
    assert s.connections[0].policy_map() == {"buffer": 4}
    assert hash(s) == hash(InstanceSpec.from_json(s.to_json()))


def test_defaults():
    s = InstanceSpec.from_json({"name": "A", "target": "pkg.mod:Thing"})
    assert (s.component, s.launcher, s.desired, s.role) == (
        "Thing",
        "python",
        LifecycleState.ACTIVE,
        "active",
    )
    e = InstanceSpec.from_json({"name": "B", "launcher": "exec", "target": ["/bin/x", "-v"]})
    assert e.target == ("/bin/x", "-v")
    assert e.component == "B"
    sc = InstanceSpec.from_json({"name": "C", "launcher": "script", "target": "dir/cam.py"})
    assert sc.component == "cam"


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"name": "../x"}, "instance.name"),
        ({"name": None}, "instance.name"),
        ({"launcher": "docker"}, "instance.launcher"),
        ({"target": "no_colon"}, "instance.target"),
        ({"launcher": "exec", "target": "ls"}, "instance.target"),
        ({"params": [1]}, "instance.params"),
        ({"desired": "running"}, "instance.desired"),
        ({"role": "primary"}, "instance.role"),
        ({"extra": 1}, "instance.extra"),
        ({"connections": {}}, "instance.connections"),
        ({"connections": [{"out": "o", "to": "B"}]}, "instance.connections[0].in"),
        (
            {"connections": [{"out": "o", "to": "B", "in": "i", "policy": {"buffer": 0}}]},
            "instance.connections[0].policy.buffer",
        ),
        (
            {"connections": [{"out": "o", "to": "B", "in": "i", "policy": {"push": "most"}}]},
            "instance.connections[0].policy.push",
        ),
        (
            {"connections": [{"out": "o", "to": "B", "in": "i", "to_addr": "http://x"}]},
            "instance.connections[0].to_addr",
        ),
        (
            {
                "connections": [
                    {"out": "o", "to": "B", "in": "i"},
                    {"out": "o", "to": "B", "in": "i"},
                ]
            },
            "instance.connections[1].id",
        ),
    ],
)
def test_errors_name_the_field(change, field):
    doc = {**FULL, **change}
    with pytest.raises(SpecError) as info:
        InstanceSpec.from_json(doc)
    assert info.value.field == field
    assert f"field '{field}'" in str(info.value)


def test_not_an_object():
    with pytest.raises(SpecError, match="instances\\[2\\]"):
        InstanceSpec.from_json([1], "instances[2]")


COMPOSITE = "periodic:20;Cam=components.camera:Camera;Det=components.anomaly:Detector"


def test_a_composite_spec_and_its_member_ports() -> None:
    doc = {
        "name": "Vision",
        "launcher": "composite",
        "target": COMPOSITE,
        "params": {"Cam.fps": 5},
        "connections": [{"out": "Det.alarm", "to": "Ctl", "in": "alarm"}],
    }
    spec = InstanceSpec.from_json(doc)
    assert spec.component == "Vision"  # not the member class's name
    assert spec.connections[0].out_port == "Det.alarm"
    assert spec.connections[0].id == "Vision.Det.alarm->Ctl.alarm"
    assert InstanceSpec.from_json(spec.to_json()) == spec
    # a receiver may be a composite: `in` may name a member's port
    plain = {
        "name": "Ctl",
        "target": "a.b:C",
        "connections": [{"out": "o", "to": "V", "in": "M.i"}],
    }
    assert InstanceSpec.from_json(plain).connections[0].in_port == "M.i"


@pytest.mark.parametrize(
    ("doc", "field", "message"),
    [
        (
            {"name": "A", "target": "a.b:C", "connections": [{"out": "M.o", "to": "B", "in": "i"}]},
            "instance.connections[0].out",
            "an identifier",
        ),
        (
            {"name": "V", "launcher": "composite", "target": "periodic:0;Cam=a.b:C"},
            "instance.target",
            "periodic:HZ",
        ),
        (
            {"name": "V", "launcher": "composite", "target": "stepped"},
            "instance.target",
            "at least one member",
        ),
        (
            {"name": "V", "launcher": "composite", "target": "stepped;A=a.b:C;A=a.b:D"},
            "instance.target",
            "given twice",
        ),
        (
            {"name": "V", "launcher": "composite", "target": "stepped;A=file.py"},
            "instance.target",
            "package.module:Class",
        ),
    ],
)
def test_composite_spec_errors(doc: dict[str, Any], field: str, message: str) -> None:
    with pytest.raises(SpecError) as info:
        InstanceSpec.from_json(doc)
    assert info.value.field == field
    assert message in str(info.value)
