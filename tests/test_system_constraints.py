"""Per-component Table I thresholds, per-connection Table II bounds and the `compliance:`
section in system files: what loads, and each mistake reported with file:line and field."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from sdrpeer.cli.main import main
from sdrpeer.errors import SystemFileError
from sdrpeer.system.loader import TOP_KEYS, parse_system, schema_path
from sdrpeer.system.model import ComplianceDef, Thresholds, system_from_json
from sdrpeer.system.sections import COMPLIANCE_KEYS, LINK_KEYS, ROBOT_KEYS

CAM = "components.camera:Camera"
DET = "components.anomaly_detection:AnomalyDetection"
MB = 1000**2

GOOD = f"""name: s
components:
  - name: Cam
    target: {CAM}
    constraints: {{cpu_below: 50%, mem_free_above: 800MB, battery_above: 40%}}
  - {{name: Det, target: {DET}}}
connections:
  - from: Cam.image
    to: Det.image
    constraints: {{delay_below: 20ms, loss_below: 5%, jitter_below: 4ms, rssi_above: -60dBm,
                  distance_below: 30m}}
allocation:
  constraints: {{cpu_below: 80%, mem_free_above: 500MB, delay_below: 100ms}}
compliance: {{on_violation: replace, for: 3s, clear: 15%, min_interval: 120s}}
"""


def test_own_thresholds_and_bounds_load_in_base_units() -> None:
    system = parse_system(GOOD, "sys.yaml")
    cam = system.component("Cam")
    assert cam.thresholds == Thresholds(
        cpu_below_pct=50.0, mem_free_above_bytes=800 * MB, battery_above_pct=40.0
    )
    assert system.component("Det").thresholds == Thresholds()
    (conn,) = system.connections
    assert conn.bounds == Thresholds(
        rssi_above_dbm=-60.0,
        jitter_below_ms=4.0,
        distance_below_m=30.0,
        loss_below=0.05,
        delay_below_ms=20.0,
    )
    assert system.compliance == ComplianceDef("replace", 3.0, 0.15, 120.0)
    # the tightest of everything: what records list links at and publish at
    tight = system.tightest_thresholds()
    assert (tight.cpu_below_pct, tight.mem_free_above_bytes, tight.delay_below_ms) == (
        50.0,
        800 * MB,
        20.0,
    )
    # the plan carries them: a peer rebuilds the same system
    again = system_from_json(json.loads(json.dumps(system.to_json())))
    assert again == system
    assert again.digest() == system.digest()


def test_defaults_report_after_five_seconds() -> None:
    system = parse_system(f"name: s\ncomponents: [{{name: C, target: {CAM}}}]\n", "sys.yaml")
    assert system.compliance == ComplianceDef("report", 5.0, 0.1, 60.0)
    assert system.component("C").thresholds == Thresholds()


@pytest.mark.parametrize(
    ("fleet", "own", "expected"),
    [
        (Thresholds(cpu_below_pct=80), Thresholds(cpu_below_pct=50), Thresholds(cpu_below_pct=50)),
        (Thresholds(cpu_below_pct=80), Thresholds(cpu_below_pct=90), Thresholds(cpu_below_pct=80)),
        (Thresholds(), Thresholds(battery_above_pct=30), Thresholds(battery_above_pct=30)),
        (
            Thresholds(mem_free_above_bytes=500, rssi_above_dbm=-70),
            Thresholds(mem_free_above_bytes=800, rssi_above_dbm=-60),
            Thresholds(mem_free_above_bytes=800, rssi_above_dbm=-60),
        ),
        (
            Thresholds(delay_below_ms=100, loss_below=0.3),
            Thresholds(delay_below_ms=20),
            Thresholds(delay_below_ms=20, loss_below=0.3),
        ),
    ],
)
def test_stricter_takes_the_narrower_bound(
    fleet: Thresholds, own: Thresholds, expected: Thresholds
) -> None:
    assert fleet.stricter(own) == expected
    assert own.stricter(fleet) == expected


HEAD = f"name: s\ncomponents:\n  - {{name: C, target: {CAM}}}\n  - {{name: D, target: {DET}}}\n"
"""Lines 1-4; cases append from line 5."""
CONN = HEAD + "connections:\n  - from: C.image\n    to: D.image\n"
"""Lines 1-7; a connection's constraints go on line 8."""

ERRORS = [
    (
        "a Table II key on a component",
        HEAD + f"  - {{name: E, target: {CAM}, constraints: {{delay_below: 20ms}}}}\n",
        "sys.yaml:5: field 'components[2].constraints.delay_below': delay_below is not allowed "
        "here: it goes under a connection's constraints (here: cpu_below, mem_free_above, "
        "battery_above)",
    ),
    (
        "a Table I key on a connection",
        CONN + "    constraints: {battery_above: 30%}\n",
        "sys.yaml:8: field 'connections[0].constraints.battery_above': battery_above is not "
        "allowed here: it goes under a component's constraints",
    ),
    (
        "an unknown key on a connection",
        CONN + "    constraints: {latency_below: 20ms}\n",
        "sys.yaml:8: field 'connections[0].constraints.latency_below': unknown field",
    ),
    (
        "a bad delay",
        CONN + "    constraints: {delay_below: fast}\n",
        "sys.yaml:8: field 'connections[0].constraints.delay_below'",
    ),
    (
        "a loss of 0",
        CONN + "    constraints: {loss_below: 0%}\n",
        "sys.yaml:8: field 'connections[0].constraints.loss_below': '0%' is out of range",
    ),
    (
        "a component threshold out of range",
        HEAD + f"  - {{name: E, target: {CAM}, constraints: {{cpu_below: 120%}}}}\n",
        "sys.yaml:5: field 'components[2].constraints.cpu_below': '120%' is out of range",
    ),
    (
        "constraints not a mapping",
        CONN + "    constraints: [delay_below]\n",
        "sys.yaml:8: field 'connections[0].constraints': expected a mapping",
    ),
    (
        "an unknown policy",
        HEAD + "compliance:\n  on_violation: shuffle\n",
        "sys.yaml:6: field 'compliance.on_violation': expected one of report, replace, "
        "got 'shuffle'",
    ),
    (
        "a hysteresis too wide",
        HEAD + "compliance: {clear: 50%}\n",
        "sys.yaml:5: field 'compliance.clear': '50%' is out of range (0% to 20%)",
    ),
    (
        "a negative sustain",
        HEAD + "compliance: {for: -1s}\n",
        "sys.yaml:5: field 'compliance.for'",
    ),
    (
        "an unknown compliance key",
        HEAD + "compliance: {sustain: 3s}\n",
        "sys.yaml:5: field 'compliance.sustain': unknown field (known: on_violation, for, clear, "
        "min_interval)",
    ),
]


@pytest.mark.parametrize(("text", "expected"), [c[1:] for c in ERRORS], ids=[c[0] for c in ERRORS])
def test_mistakes_name_file_line_and_field(text: str, expected: str) -> None:
    with pytest.raises(SystemFileError) as e:
        parse_system(text, "sys.yaml")
    assert any(p.startswith(expected) for p in e.value.problems), e.value.problems


def test_every_mistake_is_reported_in_one_pass() -> None:
    text = (
        HEAD
        + f"  - {{name: E, target: {CAM}, constraints: {{loss_below: 5%}}}}\n"  # line 5
        + "connections:\n  - from: C.image\n    to: D.image\n"
        + "    constraints: {cpu_below: 50%}\n"  # line 9
        + "compliance: {on_violation: move}\n"  # line 10
    )
    with pytest.raises(SystemFileError) as e:
        parse_system(text, "sys.yaml")
    lines = [p.split(":")[1] for p in e.value.problems]
    assert lines == ["5", "9", "10"], e.value.problems


def schema() -> dict[str, Any]:
    doc: dict[str, Any] = json.loads(schema_path().read_text(encoding="utf-8"))
    return doc


def test_schema_knows_the_new_keys() -> None:
    s = schema()
    d = s["$defs"]
    assert set(s["properties"]) == set(TOP_KEYS)
    assert set(s["properties"]["compliance"]["properties"]) == set(COMPLIANCE_KEYS)
    assert set(d["robot_constraints"]["properties"]) == set(ROBOT_KEYS)
    assert set(d["link_constraints"]["properties"]) == set(LINK_KEYS)
    assert d["component"]["properties"]["constraints"] == {"$ref": "#/$defs/robot_constraints"}
    assert d["connection"]["properties"]["constraints"] == {"$ref": "#/$defs/link_constraints"}


def test_the_schema_accepts_the_good_file_and_refuses_a_misplaced_key() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(schema())
    assert [e.message for e in validator.iter_errors(yaml.safe_load(GOOD))] == []
    bad = yaml.safe_load(CONN + "    constraints: {battery_above: 30%}\n")
    assert list(validator.iter_errors(bad))


def test_system_check_shows_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "sys.yaml"
    path.write_text(GOOD)
    assert main(["system", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert (
        "own thresholds {'cpu_below_pct': 50.0, 'mem_free_above_bytes': 800000000, "
        "'battery_above_pct': 40.0}" in out
    )
    assert "Cam.image->Det.image" in out
    assert "own bounds {'rssi_above_dbm': -60.0, 'jitter_below_ms': 4.0" in out
    assert "compliance: replace after 3s, clears 15% inside, at most one move per 120s" in out


def test_a_composite_takes_its_own_thresholds() -> None:
    text = f"""name: s
composites:
  - name: Vision
    execution: {{periodic: 10}}
    members:
      - {{name: Cam, target: {CAM}}}
      - {{name: Det, target: {DET}}}
    constraints: {{battery_above: 30%}}
components:
  - {{name: C, target: {CAM}}}
"""
    system = parse_system(text, "sys.yaml")
    assert system.component("Vision").thresholds == Thresholds(battery_above_pct=30.0)
