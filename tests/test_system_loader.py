"""System files that load: the values they give (units, profile merge, defaults)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from sdrpeer.system.loader import load_system, parse_system
from sdrpeer.system.model import (
    RecoveryRule,
    Requirements,
    StandbySpec,
    SystemDef,
    Thresholds,
    system_from_json,
)
from sdrpeer.system.recovery_defaults import LOCAL_FIRST, MOVE, default_recovery

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "examples" / "paper"
MB = 1_000_000

PROFILE = """\
component: Camera
target: components.camera:Camera
params: {reserve_mb: 0}
cpu: {mean_pct: 2.5, peak_pct: 9.8, samples: 98}
memory: {peak_rss: 30000000, peak_rss_human: 30MB, mean_rss: 29000000}
ports:
  image: {direction: out, frames_per_s: 10.0, bytes_per_s: 190000.5}
inputs: {}
"""


def load(tmp_path: Path, text: str) -> SystemDef:
    """Write a system file (and a camera profile next to it) and load it."""
    (tmp_path / "cam.yaml").write_text(PROFILE)
    path = tmp_path / "system.yaml"
    path.write_text(textwrap.dedent(text))
    return load_system(path)


def test_paper_system() -> None:
    s = load_system(PAPER / "system.yaml")
    assert s.name == "paper-demo"
    assert [c.name for c in s.components] == [
        "OmnidirectionalCameraRTC",
        "AnomalyDetectionRTC",
        "CameraRTC",
        "REDControllerRTC",
        "PositionEstimationRTC",
    ]
    for c in s.components:
        assert c.params_map() == {"reserve_mb": 500}
        assert c.standby == StandbySpec(same_robot=0, other_robots=1, mode="cold")
        assert c.launcher == "python"
    cam = s.component("CameraRTC")
    assert cam.requires.mem_bytes == 549625856  # profiled with the reserve
    assert cam.requires.cpu_pct == 1.44
    det = s.component("AnomalyDetectionRTC")
    assert det.requires.mem_bytes == 550 * MB  # inline override of a profile without reserve
    assert det.requires.cpu_pct == 0.9  # still the profile's
    assert det.requires.port_rate("alarm") == 517.4
    assert det.requires.profile == "../../profiles/anomaly_detection.yaml"
    assert s.allocation.strategy == "first_fit"
    assert s.allocation.thresholds == Thresholds(mem_free_above_bytes=500 * MB)
    ids = [c.id for c in s.connections]
    assert ids[0] == "OmnidirectionalCameraRTC.image->AnomalyDetectionRTC.image"
    assert s.connections[0].traffic_bytes_per_s == 511697.5
    assert s.connections[0].policy == (("buffer", 1), ("push", "new"))
    rules = {r.cause: r for r in s.recovery.rules}
    assert rules["memory_shortage"] == RecoveryRule(
        "memory_shortage", "mem_free", "<=", 200 * MB, 0.0, 250 * MB, LOCAL_FIRST
    )
    assert rules["communication_failure"] == RecoveryRule(
        "communication_failure", "rssi", "<=", -52.5, 6.0, -50.0, MOVE
    )
    assert s.source == str(PAPER / "system.yaml")


def test_small_paper_system_is_the_same_without_the_reserve() -> None:
    big = load_system(PAPER / "system.yaml")
    small = load_system(PAPER / "system-small.yaml")
    assert [c.name for c in small.components] == [c.name for c in big.components]
    assert [c.id for c in small.connections] == [c.id for c in big.connections]
    assert [c.policy for c in small.connections] == [c.policy for c in big.connections]
    assert small.recovery == big.recovery
    assert small.allocation == big.allocation
    for c in small.components:
        assert c.params_map() == {"reserve_mb": 0}
        assert 20 * MB < c.requires.mem_bytes < 30 * MB


def test_units_are_converted_to_base_units(tmp_path: Path) -> None:
    s = load(
        tmp_path,
        """\
        version: 1
        name: units
        components:
          - name: Cam
            target: components.camera:Camera
            requires: {cpu: 5%, memory: 520MB, traffic: {image: 200kB/s}}
            pin: robot-2
            prefer: [robot-1, robot-3]
            standby: {same_robot: 1, other_robots: 2, mode: cold, sync: 500ms}
            watchdog: 1500ms
        allocation:
          strategy: objective
          constraints:
            cpu_below: 80%
            mem_free_above: 0.5GiB
            battery_above: 20%
            rssi_above: -60dBm
            jitter_below: 20ms
            distance_below: 0.03km
            loss_below: 10%
            delay_below: 0.1s
          weights: {mem_free: 1, battery: 0.5, rssi: 0.5, distance: 0.2, traffic_local: 1, load: 0}
          plugins: [memory, rssi]
          preempt: true
        recovery:
          max_attempts: 5
          window: 2min
          min_dwell: 500ms
        """,
    )
    cam = s.component("Cam")
    assert cam.requires == Requirements(5.0, 520 * MB, (("image", 200_000.0),), None)
    assert cam.pin == "robot-2"
    assert cam.prefer == ("robot-1", "robot-3")
    assert cam.standby == StandbySpec(1, 2, "cold", sync_s=0.5)
    assert cam.watchdog_s == 1.5
    a = s.allocation
    assert a.strategy == "objective"
    assert a.thresholds == Thresholds(
        cpu_below_pct=80.0,
        mem_free_above_bytes=512 * 1024 * 1024,
        battery_above_pct=20.0,
        rssi_above_dbm=-60.0,
        jitter_below_ms=20.0,
        distance_below_m=30.0,
        loss_below=0.1,
        delay_below_ms=100.0,
    )
    assert a.weights == (
        ("battery", 0.5),
        ("distance", 0.2),
        ("load", 0.0),
        ("mem_free", 1.0),
        ("rssi", 0.5),
        ("traffic_local", 1.0),
    )
    assert a.constraints == ("memory", "rssi")
    assert a.preempt is True
    r = s.recovery
    assert (r.max_attempts, r.window_s, r.min_dwell_s) == (5, 120.0, 0.5)
    assert r.rules == default_recovery().rules  # no rules given: Table III


def test_profile_merge_inline_wins(tmp_path: Path) -> None:
    s = load(
        tmp_path,
        """\
        name: merge
        components:
          - {name: A, target: components.camera:Camera, profile: cam.yaml}
          - name: B
            target: components.camera:Camera
            profile: cam.yaml
            requires: {memory: 520MB, traffic: {image: 1MB/s}}
          - {name: D, target: components.anomaly_detection:AnomalyDetection}
          - {name: E, target: components.anomaly_detection:AnomalyDetection}
        connections:
          - {from: A.image, to: D.image}
          - {from: B.image, to: D.image}
          - {from: B.image, to: E.image, traffic: 3kB/s}
        """,
    )
    assert s.name == "merge"
    a, b = s.component("A"), s.component("B")
    assert a.requires == Requirements(2.5, 30 * MB, (("image", 190000.5),), "cam.yaml")
    assert b.requires == Requirements(2.5, 520 * MB, (("image", 1e6),), "cam.yaml")
    assert s.component("D").requires == Requirements()
    assert [c.traffic_bytes_per_s for c in s.connections] == [190000.5, 1e6, 3000.0]


def test_no_profile_no_requires_means_zero_and_unknown_traffic(tmp_path: Path) -> None:
    s = load(
        tmp_path,
        """\
        name: bare
        components:
          - {name: C, target: components.camera:Camera}
          - {name: D, target: components.anomaly_detection:AnomalyDetection}
        connections:
          - {from: C.image, to: D.image}
        """,
    )
    assert s.connections[0].traffic_bytes_per_s is None
    assert s.component("C").requires == Requirements()


def test_defaults_when_sections_are_absent(tmp_path: Path) -> None:
    s = load(tmp_path, "name: d\ncomponents: [{name: C, target: components.camera:Camera}]\n")
    assert s.connections == ()
    assert s.allocation.strategy == "first_fit"
    assert s.allocation.thresholds == Thresholds()
    assert s.recovery == default_recovery()
    c = s.component("C")
    assert (c.pin, c.prefer, c.standby, c.params) == (None, (), StandbySpec(), ())


def test_default_recovery_is_table_three() -> None:
    rules = default_recovery().rules
    by = {(r.cause, r.metric): r for r in rules}
    assert by["memory_shortage", "mem_free"].threshold == 200 * MB
    assert by["memory_shortage", "mem_free"].actions == (
        "standby_same_robot",
        "restart",
        "standby_other_robot",
        "launch_other_robot",
    )
    assert by["cpu_high", "cpu"].op == ">="
    assert by["cpu_high", "cpu"].sustain_s == 5.0
    assert by["cpu_high", "cpu"].actions == LOCAL_FIRST
    for event in ("component_error", "hardware_failure", "abnormal_behaviour", "emergency_stop"):
        assert by[event, None].actions == MOVE
    assert by["low_battery", "battery"].threshold == 15.0
    rssi = by["communication_failure", "rssi"]
    assert (rssi.threshold, rssi.sustain_s, rssi.op) == (-52.5, 6.0, "<=")
    for metric in ("delay", "jitter", "loss"):
        assert by["communication_failure", metric].op == ">="
    for r in rules:  # clear levels sit on the healthy side
        if r.clear is not None and r.threshold is not None:
            assert r.clear >= r.threshold if r.op in ("<", "<=") else r.clear <= r.threshold


def test_recovery_rules_replace_the_defaults(tmp_path: Path) -> None:
    s = load(
        tmp_path,
        """\
        name: r
        components: [{name: C, target: components.camera:Camera}]
        recovery:
          rules:
            - {cause: low_battery, when: battery < 10, clear: 12%, actions: [launch_other_robot]}
            - {cause: communication_failure, when: "jitter >= 40ms", for: 3s, actions: [restart]}
            - {cause: communication_failure, when: loss > 25%, actions: [restart]}
            - {cause: hardware_failure, actions: [standby_other_robot]}
        """,
    )
    assert s.recovery.rules == (
        RecoveryRule("low_battery", "battery", "<", 10.0, 0.0, 12.0, ("launch_other_robot",)),
        RecoveryRule("communication_failure", "jitter", ">=", 40.0, 3.0, None, ("restart",)),
        RecoveryRule("communication_failure", "loss", ">", 0.25, 0.0, None, ("restart",)),
        RecoveryRule("hardware_failure", actions=("standby_other_robot",)),
    )


def test_other_launchers_take_their_ports_on_trust(tmp_path: Path) -> None:
    (tmp_path / "nodes").mkdir()
    (tmp_path / "nodes" / "viewer.py").write_text("# the viewer\n")
    s = load(
        tmp_path,
        """\
        name: launchers
        components:
          - {name: Tool, launcher: exec, target: [/usr/bin/tool, --fast], params: {level: 3}}
          - {name: Script, launcher: script, target: "nodes/viewer.py:Viewer"}
        connections:
          - {from: Tool.anything, to: Script.whatever}
        """,
    )
    assert s.component("Tool").target == ("/usr/bin/tool", "--fast")
    assert s.component("Tool").params == (("level", 3),)
    assert s.component("Script").target == f"{tmp_path.resolve()}/nodes/viewer.py:Viewer"
    assert s.connections[0].id == "Tool.anything->Script.whatever"


def test_params_are_checked_and_kept_as_written(tmp_path: Path) -> None:
    s = load(
        tmp_path,
        """\
        name: p
        components:
          - {name: C, target: components.camera:Camera, params: {rate: 5, width: 320, seed: 7}}
        """,
    )
    assert s.component("C").params == (("rate", 5), ("seed", 7), ("width", 320))


def test_parse_system_resolves_profiles_against_base_dir(tmp_path: Path) -> None:
    (tmp_path / "cam.yaml").write_text(PROFILE)
    text = "name: t\ncomponents: [{name: C, target: components.camera:Camera, profile: cam.yaml}]"
    s = parse_system(text, "inline.yaml", base_dir=tmp_path)
    assert s.component("C").requires.cpu_pct == 2.5
    assert s.source == "inline.yaml"


@pytest.mark.parametrize("name", ["system.yaml", "system-small.yaml"])
def test_json_round_trip_and_digest(name: str) -> None:
    s = load_system(PAPER / name)
    back = system_from_json(s.to_json())
    assert back == s
    assert back.digest() == s.digest()
    assert load_system(PAPER / name).digest() == s.digest()
