"""The system file's `composites:` section: a composite loads as one component (composite
launcher, `Member.param` params, summed requirements), connections address members' ports as
`Member.port`, and every wrong composite is reported with file:line and the dotted field."""

from __future__ import annotations

import pytest

from sdrpeer.errors import SystemFileError
from sdrpeer.launch.composite import parse_composite
from sdrpeer.system.loader import parse_system

CAM = "components.camera:Camera"
DET = "components.anomaly_detection:AnomalyDetection"
CTL = "components.red_controller:REDController"
GOOD = f"""\
name: s
components:
  - {{name: Ctl, target: {CTL}}}
composites:
  - name: Vision
    execution: {{periodic: 20}}
    pin: robot-1
    members:
      - {{name: Cam, target: {CAM}, params: {{rate: 5}}, requires: {{cpu: 10%, memory: 30MB,
          traffic: {{image: 200kB/s}}}}}}
      - {{name: Det, target: {DET}, requires: {{cpu: 5%, memory: 20MB}}}}
connections:
  - {{from: Cam.image, to: Det.image}}
  - {{from: Det.alarm, to: Ctl.alarm}}
"""


def test_a_composite_is_one_component_with_member_ports() -> None:
    system = parse_system(GOOD, "sys.yaml")
    assert [c.name for c in system.components] == ["Ctl", "Vision"]
    vision = system.component("Vision")
    assert vision.launcher == "composite"
    assert vision.pin == "robot-1"
    target = parse_composite(str(vision.target))
    assert target.hz == 20.0
    assert target.members == (("Cam", CAM), ("Det", DET))  # in execution order
    assert vision.params == (("Cam.rate", 5.0),)
    assert vision.requires.cpu_pct == pytest.approx(15.0)
    assert vision.requires.mem_bytes == 50_000_000
    assert vision.requires.out_bytes_per_s == (("Cam.image", 200_000.0),)
    inner, out = system.connections
    assert (inner.from_component, inner.from_port) == ("Vision", "Cam.image")
    assert (inner.to_component, inner.to_port) == ("Vision", "Det.image")
    assert inner.traffic_bytes_per_s == 200_000.0  # the member's traffic, as Member.port
    assert out.id == "Vision.Det.alarm->Ctl.alarm"


def test_a_stepped_composite() -> None:
    text = GOOD.replace("execution: {periodic: 20}", "execution: stepped")
    vision = parse_system(text, "sys.yaml").component("Vision")
    assert parse_composite(str(vision.target)).hz is None


ERRORS: list[tuple[str, str, str]] = [
    (
        "no members",
        GOOD.split("    members:", maxsplit=1)[0] + "    members: []\n",
        "sys.yaml:8: field 'composites[0].members': a composite needs at least one member",
    ),
    (
        "unknown member class",
        GOOD.replace(f"name: Det, target: {DET}", "name: Det, target: components.camera:Nope"),
        "sys.yaml:11: field 'composites[0].members[1].target': cannot import the component class",
    ),
    (
        "member also a component",
        GOOD.replace("name: Ctl,", "name: Cam,").replace("to: Ctl.alarm", "to: Cam.image"),
        "sys.yaml:9: field 'composites[0].members[0].name': 'Cam' is also a component (line 3)",
    ),
    (
        "member in two composites",
        GOOD.replace(
            "connections:",
            f"  - {{name: Other, execution: stepped, members: [{{name: Det, target: {DET}}}]}}\n"
            "connections:",
        ),
        "sys.yaml:12: field 'composites[1].members[0].name': 'Det' is already a member of Vision",
    ),
    (
        "non-python member",
        GOOD.replace(f"name: Det, target: {DET}", "name: Det, launcher: script, target: d.py"),
        "sys.yaml:11: field 'composites[0].members[1].launcher': a member runs in its composite",
    ),
    (
        "bad context",
        GOOD.replace("execution: {periodic: 20}", "execution: {periodic: 0}"),
        "sys.yaml:6: field 'composites[0].execution': expected stepped or {periodic: HZ}",
    ),
    (
        "missing name, its members' ports connected",
        GOOD.replace("  - name: Vision\n", "  - nombre: Vision\n"),
        "sys.yaml:5: field 'composites[0].name': missing (required)",
    ),
    (
        "missing members, their ports connected",
        GOOD.split("    members:", maxsplit=1)[0]
        + "connections:\n  - {from: Cam.image, to: Ctl.alarm}\n",
        "sys.yaml:5: field 'composites[0].members': missing (required)",
    ),
    (
        "missing context",
        GOOD.replace("    execution: {periodic: 20}\n", ""),
        "sys.yaml:5: field 'composites[0].execution': missing (required)",
    ),
    (
        "member name not an identifier",
        GOOD.replace("name: Det,", "name: De-t,").replace("Det.", "De-t."),
        "sys.yaml:11: field 'composites[0].members[1].name': a member's name must be an identifier",
    ),
    (
        "member param refused by its class",
        GOOD.replace("params: {rate: 5}", "params: {rate: -1}"),
        "sys.yaml:9: field 'composites[0].members[0].params.rate'",
    ),
    (
        "unknown member key",
        GOOD.replace("params: {rate: 5}", "pin: robot-2"),
        "sys.yaml:9: field 'composites[0].members[0].pin': unknown field",
    ),
    (
        "member port that is not there",
        GOOD.replace("from: Cam.image", "from: Cam.video"),
        "sys.yaml:13: field 'connections[0].from': Camera has no port 'video'",
    ),
    (
        "composite named like a component",
        GOOD.replace("name: Vision", "name: Ctl"),
        "sys.yaml:5: field 'composites[0].name': 'Ctl' given twice (first at line 3)",
    ),
]


@pytest.mark.parametrize(("text", "expected"), [c[1:] for c in ERRORS], ids=[c[0] for c in ERRORS])
def test_composite_errors(text: str, expected: str) -> None:
    with pytest.raises(SystemFileError) as info:
        parse_system(text, "sys.yaml")
    assert expected in str(info.value), str(info.value)
