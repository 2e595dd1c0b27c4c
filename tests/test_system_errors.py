"""Broken system files: each problem is reported with file:line and the dotted field."""

from __future__ import annotations

from pathlib import Path

import pytest

from sdrpeer.errors import ConfigError, SystemFileError
from sdrpeer.system.loader import load_system, parse_system

CAM = "components.camera:Camera"
DET = "components.anomaly_detection:AnomalyDetection"
HEAD = f"name: s\ncomponents:\n  - {{name: C, target: {CAM}}}\n  - {{name: D, target: {DET}}}\n"
"""Lines 1-4: a valid start; cases append from line 5."""
RULES = HEAD + "recovery:\n  rules:\n"
"""Lines 1-6; the first rule is on line 7."""

CASES: list[tuple[str, str, str]] = [
    ("not yaml", "name: [s\n", "sys.yaml:2: not valid YAML"),
    ("top is a list", "- a\n", "sys.yaml:1: expected a mapping with version, name"),
    ("unknown top key", HEAD + "colour: red\n", "sys.yaml:5: field 'colour': unknown field"),
    ("missing components", "name: s\n", "sys.yaml:1: field 'components': missing (required)"),
    ("missing name", f"components: [{{name: C, target: {CAM}}}]\n", "field 'name': missing"),
    ("bad version", HEAD + "version: 2\n", "sys.yaml:5: field 'version': unsupported version 2"),
    ("bad system name", HEAD.replace("name: s", "name: a b"), "sys.yaml:1: field 'name': expected"),
    ("no components", "name: s\ncomponents: []\n", "sys.yaml:2: field 'components': a system"),
    (
        "duplicate component",
        HEAD + f"  - {{name: C, target: {CAM}}}\n",
        "sys.yaml:5: field 'components[2].name': 'C' given twice (first at line 3)",
    ),
    (
        "unknown component key",
        HEAD + f"  - {{name: E, target: {CAM}, replicas: 2}}\n",
        "sys.yaml:5: field 'components[2].replicas': unknown field",
    ),
    (
        "missing target",
        HEAD + "  - {name: E}\n",
        "sys.yaml:5: field 'components[2].target': missing (required)",
    ),
    (
        "bad component name",
        HEAD + f"  - {{name: 'E F', target: {CAM}}}\n",
        "sys.yaml:5: field 'components[2].name': expected a name",
    ),
    (
        "unknown launcher",
        HEAD + f"  - {{name: E, target: {CAM}, launcher: docker}}\n",
        "sys.yaml:5: field 'components[2].launcher': expected one of composite, exec, openrtm, "
        "python",
    ),
    (
        "python target form",
        HEAD + "  - {name: E, target: components/camera.py}\n",
        "sys.yaml:5: field 'components[2].target': expected package.module:Class",
    ),
    (
        "exec target not a list",
        HEAD + "  - {name: E, launcher: exec, target: /bin/tool}\n",
        "sys.yaml:5: field 'components[2].target': exec needs an argv list",
    ),
    (
        "class cannot be imported",
        HEAD + "  - {name: E, target: 'nosuch.mod:Thing'}\n",
        "sys.yaml:5: field 'components[2].target': cannot import the component class: "
        "nosuch.mod:Thing: no module named 'nosuch'",
    ),
    (
        "class not in module",
        HEAD + "  - {name: E, target: 'components.camera:Nope'}\n",
        "sys.yaml:5: field 'components[2].target': cannot import the component class",
    ),
    (
        "unknown param",
        HEAD + f"  - {{name: E, target: {CAM}, params: {{fps: 3}}}}\n",
        "sys.yaml:5: field 'components[2].params.fps': Camera declares no param 'fps'",
    ),
    (
        "bad param value",
        HEAD + f"  - {{name: E, target: {CAM}, params: {{width: 2}}}}\n",
        "sys.yaml:5: field 'components[2].params.width': param 'width': 2 below min 16",
    ),
    (
        "param value a mapping",
        HEAD + f"  - {{name: E, target: {CAM}, params: {{seed: {{a: 1}}}}}}\n",
        "sys.yaml:5: field 'components[2].params.seed': expected a string, number, boolean",
    ),
    (
        "negative cpu",
        HEAD + f"  - {{name: E, target: {CAM}, requires: {{cpu: -5%}}}}\n",
        "sys.yaml:5: field 'components[2].requires.cpu': '-5%' is out of range",
    ),
    (
        "bad memory unit",
        HEAD + f"  - {{name: E, target: {CAM}, requires: {{memory: 5XB}}}}\n",
        "sys.yaml:5: field 'components[2].requires.memory': expected a size such as 500MB",
    ),
    (
        "absurd memory",
        HEAD + f"  - {{name: E, target: {CAM}, requires: {{memory: 5TB}}}}\n",
        "sys.yaml:5: field 'components[2].requires.memory': '5TB' is out of range (0 to 1TB)",
    ),
    (
        "unknown requires key",
        HEAD + f"  - {{name: E, target: {CAM}, requires: {{gpu: 1}}}}\n",
        "sys.yaml:5: field 'components[2].requires.gpu': unknown field (known: cpu, memory",
    ),
    (
        "traffic without /s",
        HEAD + f"  - {{name: E, target: {CAM}, requires: {{traffic: {{image: 20kB}}}}}}\n",
        "sys.yaml:5: field 'components[2].requires.traffic.image': expected a data rate",
    ),
    (
        "traffic of an unknown port",
        HEAD + f"  - {{name: E, target: {CAM}, requires: {{traffic: {{video: 2kB/s}}}}}}\n",
        "sys.yaml:5: field 'components[2].requires.traffic.video': no OutPort 'video' "
        "(out ports: image)",
    ),
    (
        "negative standby",
        HEAD + f"  - {{name: E, target: {CAM}, standby: {{other_robots: -1}}}}\n",
        "sys.yaml:5: field 'components[2].standby.other_robots': -1 is out of range (0 to 64)",
    ),
    (
        "bad standby mode",
        HEAD + f"  - {{name: E, target: {CAM}, standby: {{mode: warm}}}}\n",
        "sys.yaml:5: field 'components[2].standby.mode': expected one of hot, cold, got 'warm'",
    ),
    (
        "bad standby sync",
        HEAD + f"  - {{name: E, target: {CAM}, standby: {{sync: 2h}}}}\n",
        "sys.yaml:5: field 'components[2].standby.sync': '2h' is out of range (0s to 3600s)",
    ),
    (
        "watchdog too short",
        HEAD + f"  - {{name: E, target: {CAM}, watchdog: 100ms}}\n",
        "sys.yaml:5: field 'components[2].watchdog': '100ms' is out of range (0 for none, or 0.5s"
        " to 600s)",
    ),
    (
        "pin not a robot name",
        HEAD + f"  - {{name: E, target: {CAM}, pin: 'robot 2'}}\n",
        "sys.yaml:5: field 'components[2].pin': expected a robot name",
    ),
    (
        "pin longer than a robot name",
        HEAD + f"  - {{name: E, target: {CAM}, pin: {'r' * 256}}}\n",
        "sys.yaml:5: field 'components[2].pin': a robot name has at most 255 characters, got "
        f"'{'r' * 60}'... (256 characters)",
    ),
    (
        "prefer twice",
        HEAD + f"  - {{name: E, target: {CAM}, prefer: [r1, r1]}}\n",
        "sys.yaml:5: field 'components[2].prefer': 'r1' is listed twice",
    ),
    (
        "missing profile",
        HEAD + f"  - {{name: E, target: {CAM}, profile: none.yaml}}\n",
        "sys.yaml:5: field 'components[2].profile': no such profile file 'none.yaml'",
    ),
    (
        "profile of another class",
        HEAD + f"  - {{name: E, target: {DET}, profile: cam.yaml}}\n",
        "sys.yaml:5: field 'components[2].profile': cam.yaml was measured for "
        "components.camera:Camera, not components.anomaly_detection:AnomalyDetection",
    ),
    (
        "broken profile",
        HEAD + f"  - {{name: E, target: {CAM}, profile: broken.yaml}}\n",
        "sys.yaml:5: field 'components[2].profile': bad profile: broken.yaml:2: "
        "field 'memory.peak_rss': expected a number >= 0",
    ),
    (
        "connection to unknown component",
        HEAD + "connections:\n  - {from: C.image, to: X.image}\n",
        "sys.yaml:6: field 'connections[0].to': no component 'X' (known: C, D)",
    ),
    (
        "connection end without port",
        HEAD + "connections:\n  - {from: C, to: D.image}\n",
        "sys.yaml:6: field 'connections[0].from': expected Component.port, got 'C'",
    ),
    (
        "connection from an unknown port",
        HEAD + "connections:\n  - {from: C.video, to: D.image}\n",
        "sys.yaml:6: field 'connections[0].from': Camera has no port 'video' (OutPorts: image)",
    ),
    (
        "connection from an InPort",
        HEAD + "connections:\n  - {from: D.image, to: C.image}\n",
        "sys.yaml:6: field 'connections[0].from': D.image is not an OutPort of AnomalyDetection",
    ),
    (
        "connection to an OutPort",
        HEAD + "connections:\n  - {from: C.image, to: D.alarm}\n",
        "sys.yaml:6: field 'connections[0].to': D.alarm is not an InPort of AnomalyDetection "
        "(InPorts: image)",
    ),
    (
        "duplicate connection",
        HEAD + "connections:\n  - {from: C.image, to: D.image}\n  - {from: C.image, to: D.image}\n",
        "sys.yaml:7: field 'connections[1]': C.image->D.image given twice (first at line 6)",
    ),
    (
        "bad policy value",
        HEAD + "connections:\n  - {from: C.image, to: D.image, policy: {push: later}}\n",
        "sys.yaml:6: field 'connections[0].policy.push': expected one of all, fifo, skip, new",
    ),
    (
        "unknown policy key",
        HEAD + "connections:\n  - {from: C.image, to: D.image, policy: {size: 3}}\n",
        "sys.yaml:6: field 'connections[0].policy.size': unknown field",
    ),
    (
        "bad connection traffic",
        HEAD + "connections:\n  - {from: C.image, to: D.image, traffic: lots}\n",
        "sys.yaml:6: field 'connections[0].traffic': expected a data rate such as 200kB/s",
    ),
    (
        "unknown strategy",
        HEAD + "allocation: {strategy: best_fit}\n",
        "sys.yaml:5: field 'allocation.strategy': expected one of first_fit, objective, "
        "got 'best_fit'",
    ),
    (
        "unknown constraint",
        HEAD + "allocation:\n  constraints: {humidity_below: 3%}\n",
        "sys.yaml:6: field 'allocation.constraints.humidity_below': unknown field",
    ),
    (
        "cpu threshold over 100%",
        HEAD + "allocation:\n  constraints: {cpu_below: 150%}\n",
        "sys.yaml:6: field 'allocation.constraints.cpu_below': '150%' is out of range",
    ),
    (
        "rssi threshold without unit sense",
        HEAD + "allocation:\n  constraints: {rssi_above: 60dB}\n",
        "sys.yaml:6: field 'allocation.constraints.rssi_above': expected a power such as -52.5dBm",
    ),
    (
        "jitter threshold in metres",
        HEAD + "allocation:\n  constraints: {jitter_below: 20m}\n",
        "sys.yaml:6: field 'allocation.constraints.jitter_below': expected a duration",
    ),
    (
        "negative distance",
        HEAD + "allocation:\n  constraints: {distance_below: -3m}\n",
        "sys.yaml:6: field 'allocation.constraints.distance_below': expected a distance",
    ),
    (
        "unknown weight term",
        HEAD + "allocation:\n  weights: {beauty: 1}\n",
        "sys.yaml:6: field 'allocation.weights': unknown term 'beauty'",
    ),
    (
        "negative weight",
        HEAD + "allocation:\n  weights: {battery: -1}\n",
        "sys.yaml:6: field 'allocation.weights': weight of 'battery': expected 0 to 1e6",
    ),
    (
        "unknown constraint plugin",
        HEAD + "allocation:\n  plugins: [gpu]\n",
        "sys.yaml:6: field 'allocation.plugins': expected one of battery, cpu,",
    ),
    (
        "preempt not a boolean",
        HEAD + "allocation:\n  preempt: sometimes\n",
        "sys.yaml:6: field 'allocation.preempt': expected true or false",
    ),
    (
        "streams.encrypt not a boolean",
        HEAD + "streams:\n  encrypt: sometimes\n",
        "sys.yaml:6: field 'streams.encrypt': expected true or false",
    ),
    (
        "unknown streams key",
        HEAD + "streams:\n  cipher: aes\n",
        "sys.yaml:6: field 'streams.cipher': unknown",
    ),
    (
        "unknown cause",
        RULES + "    - {cause: flood, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].cause': expected one of memory_shortage",
    ),
    (
        "unknown action",
        RULES + "    - {cause: component_error, actions: [reboot]}\n",
        "sys.yaml:7: field 'recovery.rules[0].actions': expected one of standby_same_robot",
    ),
    (
        "condition syntax",
        RULES + "    - {cause: low_battery, when: battery low, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].when': expected 'METRIC OP VALUE'",
    ),
    (
        "condition unit",
        RULES + "    - {cause: memory_shortage, when: mem_free <= 2XB, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].when': expected a size such as 500MB, got '2XB'",
    ),
    (
        "condition on the wrong metric",
        RULES + "    - {cause: low_battery, when: cpu >= 90%, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].when': low_battery watches battery, not cpu",
    ),
    (
        "condition the wrong way round",
        RULES + "    - {cause: memory_shortage, when: mem_free >= 2MB, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].when': mem_free is bad when low: use < or <=",
    ),
    (
        "metric rule without when",
        RULES + "    - {cause: cpu_high, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].when': missing (required for cpu_high: cpu)",
    ),
    (
        "event with a condition",
        RULES + "    - {cause: emergency_stop, for: 2s, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].for': emergency_stop is an event: it takes no for",
    ),
    (
        "clear on the wrong side",
        RULES + "    - {cause: communication_failure, when: rssi <= -52.5dBm, "
        "clear: -60dBm, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].clear': must be at or above the threshold",
    ),
    (
        "negative sustain",
        RULES + "    - {cause: cpu_high, when: cpu > 90%, for: -1s, actions: [restart]}\n",
        "sys.yaml:7: field 'recovery.rules[0].for': expected a duration such as 6s, got '-1s'",
    ),
    (
        "duplicate rule",
        RULES + "    - {cause: component_error, actions: [restart]}\n"
        "    - {cause: component_error, actions: [restart]}\n",
        "sys.yaml:8: field 'recovery.rules[1]': a second rule for component_error "
        "(first at line 7)",
    ),
    (
        "empty actions",
        RULES + "    - {cause: component_error, actions: []}\n",
        "sys.yaml:7: field 'recovery.rules[0].actions': expected a non-empty list",
    ),
    (
        "max_attempts zero",
        HEAD + "recovery:\n  max_attempts: 0\n",
        "sys.yaml:6: field 'recovery.max_attempts': 0 is out of range (1 to 100)",
    ),
    (
        "window as a word",
        HEAD + "recovery:\n  window: soon\n",
        "sys.yaml:6: field 'recovery.window': expected a duration such as 6s, got 'soon'",
    ),
    (
        "key given twice",
        HEAD + "recovery:\n  window: 1s\n  window: 2s\n",
        "sys.yaml:7: field 'recovery.window': given twice (first at line 6)",
    ),
]

CAM_PROFILE = (
    "target: components.camera:Camera\ncpu: {mean_pct: 1.0}\nmemory: {peak_rss: 10}\nports: {}\n"
)


@pytest.fixture
def profiles(tmp_path: Path) -> Path:
    """A directory with a good camera profile and a broken one."""
    (tmp_path / "cam.yaml").write_text(CAM_PROFILE)
    (tmp_path / "broken.yaml").write_text("cpu: {mean_pct: 1.0}\nmemory: {peak_rss: lots}\n")
    return tmp_path


def test_there_are_enough_cases() -> None:
    assert len(CASES) >= 25
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize(("text", "expected"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_broken_file(profiles: Path, text: str, expected: str) -> None:
    with pytest.raises(SystemFileError) as info:
        parse_system(text, "sys.yaml", base_dir=profiles)
    assert expected in str(info.value)
    assert isinstance(info.value, ConfigError)


def test_the_head_itself_is_valid(profiles: Path) -> None:
    s = parse_system(HEAD, "sys.yaml", base_dir=profiles)
    assert [c.name for c in s.components] == ["C", "D"]


def test_all_problems_are_reported_at_once(profiles: Path) -> None:
    text = (
        "name: s\n"  # 1
        "colour: red\n"  # 2
        "components:\n"  # 3
        f"  - {{name: C, target: {CAM}, requires: {{cpu: lots, memory: -1MB}}}}\n"  # 4
        f"  - {{name: C, target: {CAM}}}\n"  # 5
        "  - {name: E, target: 'nosuch.mod:X', standby: {mode: warm}}\n"  # 6
        "connections:\n"  # 7
        "  - {from: C.image, to: Z.image}\n"  # 8
        "allocation: {strategy: best, constraints: {mem_free_above: 5XB}}\n"  # 9
        "recovery:\n"  # 10
        "  rules: [{cause: flood, actions: [pray]}]\n"  # 11
    )
    with pytest.raises(SystemFileError) as info:
        parse_system(text, "sys.yaml", base_dir=profiles)
    problems = info.value.problems
    expected = [
        "sys.yaml:2: field 'colour'",
        "sys.yaml:4: field 'components[0].requires.cpu'",
        "sys.yaml:4: field 'components[0].requires.memory'",
        "sys.yaml:5: field 'components[1].name'",
        "sys.yaml:6: field 'components[2].target'",
        "sys.yaml:6: field 'components[2].standby.mode'",
        "sys.yaml:8: field 'connections[0].to'",
        "sys.yaml:9: field 'allocation.strategy'",
        "sys.yaml:9: field 'allocation.constraints.mem_free_above'",
        "sys.yaml:11: field 'recovery.rules[0].cause'",
        "sys.yaml:11: field 'recovery.rules[0].actions'",
    ]
    assert len(problems) == len(expected)
    for problem, start in zip(problems, expected, strict=True):
        assert problem.startswith(start)
    lines = str(info.value).splitlines()
    assert lines[0] == f"sys.yaml: {len(expected)} problems"
    assert lines[1:] == problems


def test_one_problem_is_the_whole_message(profiles: Path) -> None:
    with pytest.raises(SystemFileError) as info:
        parse_system(HEAD + "colour: red\n", "sys.yaml", base_dir=profiles)
    assert str(info.value) == info.value.problems[0]
    assert len(info.value.problems) == 1


def test_unreadable_file(tmp_path: Path) -> None:
    with pytest.raises(SystemFileError, match=r"nope\.yaml: cannot read"):
        load_system(tmp_path / "nope.yaml")


def test_a_bad_component_name_is_reported_once(profiles: Path) -> None:
    text = f"name: s\ncomponents:\n  - {{name: 'a b', target: {CAM}}}\n"
    text += f"  - {{name: D, target: {DET}}}\nconnections:\n  - {{from: a b.image, to: D.image}}\n"
    with pytest.raises(SystemFileError) as info:
        parse_system(text, "sys.yaml", base_dir=profiles)
    assert len(info.value.problems) == 1
    assert info.value.problems[0].startswith("sys.yaml:3: field 'components[0].name'")


@pytest.mark.parametrize("text", ["", "# only a comment\n", "null\n"])
def test_empty_file(text: str) -> None:
    with pytest.raises(SystemFileError, match=r"^sys\.yaml(:1)?: expected a mapping with version"):
        parse_system(text, "sys.yaml")


LONG = "N" * 200_224
"""A 200 kB name, as in issue 30."""
CUT = f"'{'N' * 60}'... (200,224 characters)"
"""How every error message shows it: its first 60 characters and its length."""


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            f"name: s\ncomponents:\n  - {{name: {LONG}, target: {CAM}}}\n",
            "sys.yaml:3: field 'components[0].name': expected a name of [A-Za-z0-9_.-] (1-128), "
            f"got {CUT}",
        ),
        (
            HEAD + f"connections:\n  - {{from: {LONG}.out, to: D.image}}\n",
            f"sys.yaml:6: field 'connections[0].from': no component {CUT} (known: C, D)",
        ),
        (  # a long value with spaces (a map's repr): cut where it is echoed (errors.shown)
            "name: s\ncomponents:\n  - {name: C, target: "
            + CAM
            + ", params: {big: {"
            + ", ".join(f"k{i}: {i}" for i in range(100))
            + "}}}\n",
            "sys.yaml:3: field 'components[0].params.big': expected a string, number, boolean or "
            "a list of them, got {'k0': 0, 'k1': 1, 'k2': 2, 'k3': 3, 'k4': 4, 'k5': 5, 'k6':... "
            "(1,080 characters)",
        ),
        (  # YAML keys stop at 1024 characters
            HEAD + f"{'K' * 1000}: 1\n",
            f"sys.yaml:5: field '{'K' * 60}'... (1,000 characters): unknown field",
        ),
    ],
    ids=["component name", "connection end", "long map", "unknown key"],
)
def test_an_error_about_a_huge_value_shows_its_start_and_length(text: str, message: str) -> None:
    with pytest.raises(SystemFileError) as info:
        parse_system(text, "sys.yaml")
    assert message in str(info.value)
    assert all(len(p) < 300 for p in info.value.problems)
    assert len(str(info.value)) < 600
