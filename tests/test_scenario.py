"""Scenarios: validation with file:line:field errors, the pure changes_for timeline, and the lab
steps (agent kill/stop/restart, partition, heal) with the lab's pure script and checks."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from sdrpeer.errors import ScenarioError
from sdrpeer.lab.script import LabScript, check
from sdrpeer.monitor.scenario import Scenario
from sdrpeer.monitor.virtual import RobotFile, VirtualRobot

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
INF = math.inf

ROBOTS = [
    RobotFile(name="robot-1", memory=4_000_000_000, rssi=-47.0, position=(0.0, 0.0)),
    RobotFile(name="robot-2", memory=3_000_000_000, battery=90.0),
    RobotFile(name="robot-3", memory=4_000_000_000, position=(1.0, 3.0)),
]

TEXT = """\
steps:
  - {at: 107s, robot: robot-1, set: {rssi: -55dBm}}
  - {at: 10s, robot: robot-2, set: {drain: 2%/min}}
  - {at: 20s, robot: robot-3, move: {to: [5, 6], speed: 0.5m/s}}
  - {at: 30s, robot: robot-1, ramp: {rssi: -52dBm, over: 5s}}
"""


def scenario(text: str = TEXT) -> Scenario:
    return Scenario.parse(text, "scenarios/s.yaml", ROBOTS)


def test_set_applies_once_in_its_interval() -> None:
    s = scenario()
    assert s.changes_for("robot-2", -INF, 9.9) == {}
    assert s.changes_for("robot-2", 9.9, 10.0) == {"drain": pytest.approx(2 / 60)}
    assert s.changes_for("robot-2", 10.0, 11.0) == {}
    assert s.changes_for("robot-2", -INF, 500.0) == {"drain": pytest.approx(2 / 60)}


def test_ramp_interpolates_at_t_now() -> None:
    s = scenario()
    assert s.changes_for("robot-1", 29.0, 30.0) == {"rssi": -47.0}
    assert s.changes_for("robot-1", 30.0, 31.0) == {"rssi": pytest.approx(-48.0)}
    assert s.changes_for("robot-1", 31.0, 33.5) == {"rssi": pytest.approx(-50.5)}
    assert s.changes_for("robot-1", 34.9, 36.0) == {"rssi": -52.0}  # the end value, once
    assert s.changes_for("robot-1", 36.0, 100.0) == {}
    assert s.changes_for("robot-1", 100.0, 107.0) == {"rssi": -55.0}


def test_move_is_linear_at_speed() -> None:
    s = scenario()  # (1, 3) -> (5, 6): 5 m at 0.5 m/s = 10 s
    assert s.changes_for("robot-3", 0.0, 19.0) == {}
    assert s.changes_for("robot-3", 20.0, 22.0) == {"pos": pytest.approx((1.8, 3.6))}
    assert s.changes_for("robot-3", 22.0, 25.0) == {"pos": pytest.approx((3.0, 4.5))}
    assert s.changes_for("robot-3", 29.0, 31.0) == {"pos": (5.0, 6.0)}
    assert s.changes_for("robot-3", 31.0, 40.0) == {}
    assert s.end() == 107.0


def test_later_step_replaces_a_running_ramp_and_next_ramp_starts_from_its_value() -> None:
    s = scenario("""\
steps:
  - {at: 0s, robot: robot-1, ramp: {rssi: -67dBm, over: 20s}}
  - {at: 10s, robot: robot-1, set: {rssi: -40dBm}}
  - {at: 12s, robot: robot-1, ramp: {rssi: -50dBm, over: 10s}}
  - {at: 0s, robot: robot-1, ramp: {memory: 2GB, over: 10s}}
""")
    assert s.value_at("robot-1", "rssi", 5.0) == pytest.approx(-52.0)
    assert s.value_at("robot-1", "rssi", 11.0) == -40.0
    assert s.value_at("robot-1", "rssi", 17.0) == pytest.approx(-45.0)
    assert s.value_at("robot-1", "memory", 2.5) == 3_500_000_000
    assert isinstance(s.value_at("robot-1", "memory", 2.5), int)
    assert s.value_at("robot-2", "rssi", 5.0) is None


def test_drives_a_virtual_robot() -> None:
    s = Scenario.load(EXAMPLES / "scenarios" / "paper-rssi-drop.yaml", ROBOTS)
    robot = VirtualRobot(ROBOTS[0], lambda: (0.0, 0), start=0.0)
    seen = []
    t_prev = -INF
    for tick in range(0, 121):
        robot.set(float(tick), s.changes_for("robot-1", t_prev, float(tick)))
        t_prev = float(tick)
        seen.append(robot.sample(float(tick)).rssi_dbm)
    assert seen[106] == -47.0
    assert seen[107] == -55.0
    assert seen[120] == -55.0


def test_example_scenario_against_example_robots() -> None:
    robots = [RobotFile.load(p) for p in sorted((EXAMPLES / "robots").glob("*.yaml"))]
    s = Scenario.load(EXAMPLES / "scenarios" / "paper-rssi-drop.yaml", robots)
    assert s.robots() == {"robot-1"}
    assert s.changes_for("robot-1", 100.0, 110.0) == {"rssi": -55.0}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "steps:\n  - {at: soon, robot: robot-1, set: {rssi: -55dBm}}\n",
            "scenarios/s.yaml:2: field 'at': expected a duration such as 6s, got 'soon'",
        ),
        (
            "steps:\n  - at: 5s\n    robot: robot-1\n    set:\n      rssi: weak\n",
            "scenarios/s.yaml:5: field 'set.rssi': expected a power such as -52.5dBm, got 'weak'",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1, set: {cpu_load: 50}}\n",
            "scenarios/s.yaml:2: field 'set.cpu_load': unknown field (known: battery, drain,",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-9, set: {rssi: -55}}\n",
            "scenarios/s.yaml:2: field 'robot': unknown robot 'robot-9' (known: robot-1, robot-2,",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1}\n",
            "scenarios/s.yaml:2: a step needs exactly one of set, ramp, move",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1, set: {rssi: -5}, ramp: {rssi: -5, over: 1s}}\n",
            "scenarios/s.yaml:2: a step needs exactly one of set, ramp, move",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1, ramp: {rssi: -55dBm}}\n",
            "scenarios/s.yaml:2: field 'ramp.over': missing (required)",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1, ramp: {rssi: -55dBm, over: 0s}}\n",
            "scenarios/s.yaml:2: field 'ramp.over': expected a value above zero such as 5s",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1, ramp: {battery: 5%, over: 2s}}\n",
            "scenarios/s.yaml:2: field 'ramp.battery': unknown field (known: rssi, memory, over)",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1, move: {to: [1, 2], speed: fast}}\n",
            "scenarios/s.yaml:2: field 'move.speed': expected a speed such as 0.5m/s, got 'fast'",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1, move: {to: [1, 2, 3], speed: 1m/s}}\n",
            "scenarios/s.yaml:2: field 'move.to': expected a position such as [3, 4.5]",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-2, move: {to: [1, 2], speed: 1m/s}}\n",
            "scenarios/s.yaml:2: field 'move': robot-2 has no pos to start from",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-3, ramp: {rssi: -55dBm, over: 2s}}\n",
            "scenarios/s.yaml:2: field 'ramp.rssi': robot-3 has no rssi to start from",
        ),
        ("stepz: []\n", "scenarios/s.yaml:1: field 'stepz': unknown field (known: steps,"),
        ("description: x\n", "scenarios/s.yaml:1: field 'steps': missing (required)"),
        ("steps: {at: 5s}\n", "scenarios/s.yaml:1: field 'steps': expected a list"),
    ],
)
def test_errors_name_file_line_field(text: str, message: str) -> None:
    with pytest.raises(ScenarioError) as info:
        scenario(text)
    assert str(info.value).startswith(message), str(info.value)


def test_without_robot_files_names_are_not_checked() -> None:
    s = Scenario.parse("steps:\n  - {at: 1s, robot: anyone, set: {battery: 50%}}\n")
    assert s.changes_for("anyone", 0.0, 1.0) == {"battery": 50.0}


def test_a_fleet_scenario_is_read_by_each_robot_with_its_own_file(tmp_path: Path) -> None:
    path = tmp_path / "fleet.yaml"
    path.write_text(
        "steps:\n  - {at: 5s, robot: robot-1, set: {rssi: -55dBm}}\n"
        "  - {at: 6s, robot: robot-2, set: {battery: 10%}}\n"
    )
    with pytest.raises(ScenarioError, match="unknown robot 'robot-1'"):
        Scenario.load(path, robots=[ROBOTS[1]])
    two = Scenario.load(path, robots=[ROBOTS[1]], fleet=True)
    assert two.changes_for("robot-2", 0.0, 10.0) == {"battery": 10.0}
    assert two.changes_for("robot-1", 0.0, 10.0) == {"rssi": -55.0}


LAB = """\
steps:
  - {at: 5s, robot: robot-2, set: {drain: 60%/min}}
  - {at: 30s, robot: robot-3, agent: kill}
  - {at: 20s, partition: [[robot-1, robot-2], [robot-3]]}
  - {at: 45s, robot: robot-3, agent: restart}
  - {at: 40s, heal: true}
"""


def test_lab_steps_are_listed_in_time_order_and_change_no_robot_fact() -> None:
    s = scenario(LAB)
    steps = s.lab_steps()
    assert [(st.at, st.kind, st.robot) for st in steps] == [
        (20.0, "partition", ""),
        (30.0, "agent", "robot-3"),
        (40.0, "heal", ""),
        (45.0, "agent", "robot-3"),
    ]
    assert steps[0].values == {"groups": (("robot-1", "robot-2"), ("robot-3",))}
    assert [st.values.get("agent") for st in steps[1::2]] == ["kill", "restart"]
    assert steps[1].line == 3
    assert s.changes_for("robot-3", -INF, 100.0) == {}
    assert s.changes_for("robot-2", -INF, 100.0) == {"drain": pytest.approx(1.0)}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "steps:\n  - {at: 5s, robot: robot-1, agent: reboot}\n",
            "scenarios/s.yaml:2: field 'agent': expected one of kill, stop, restart, got 'reboot'",
        ),
        (
            "steps:\n  - {at: 5s, agent: kill}\n",
            "scenarios/s.yaml:2: field 'robot': missing (required)",
        ),
        (
            "steps:\n  - {at: 5s, robot: robot-1, heal: true}\n",
            "scenarios/s.yaml:2: field 'robot': a heal step is for the whole lab: no robot",
        ),
        (
            "steps:\n  - {at: 5s, heal: yes please}\n",
            "scenarios/s.yaml:2: field 'heal': write heal: true",
        ),
        (
            "steps:\n  - {at: 5s, partition: [[robot-1, robot-2]]}\n",
            "scenarios/s.yaml:2: field 'partition': needs at least two groups",
        ),
        (
            "steps:\n  - at: 5s\n    partition:\n      - [robot-1]\n      - [robot-9]\n",
            "scenarios/s.yaml:5: field 'partition[1]': unknown robot 'robot-9'",
        ),
        (
            "steps:\n  - {at: 5s, partition: [[robot-1], [robot-2, robot-1]]}\n",
            "scenarios/s.yaml:2: field 'partition[1]': robot-1 is in two groups",
        ),
        (
            "steps:\n  - {at: 5s, partition: [[robot-1], []]}\n",
            "scenarios/s.yaml:2: field 'partition[1]': an empty group",
        ),
    ],
)
def test_lab_step_errors_name_file_line_field(text: str, message: str) -> None:
    with pytest.raises(ScenarioError) as info:
        scenario(text)
    assert str(info.value).startswith(message), str(info.value)


def test_the_lab_script_hands_out_each_step_once_when_due() -> None:
    script = LabScript(scenario(LAB).lab_steps())
    assert script.next_at() == 20.0
    assert script.due(19.9) == []
    assert [s.kind for s in script.due(35.0)] == ["partition", "agent"]
    assert script.due(35.0) == []
    assert script.next_at() == 40.0
    assert [s.kind for s in script.due(1000.0)] == ["heal", "agent"]
    assert script.next_at() is None


def test_a_lab_refuses_steps_it_cannot_carry_out() -> None:
    steps = scenario(LAB).lab_steps()
    with pytest.raises(ScenarioError, match=r"lab.yaml:4: partition: needs the namespace lab"):
        check(steps, 3, netns=False, where="lab.yaml")
    check(steps, 3, netns=True, where="lab.yaml")
    with pytest.raises(ScenarioError, match=r"lab.yaml:4: partition: unknown robot .robot-3."):
        check(steps, 2, netns=True, where="lab.yaml")
