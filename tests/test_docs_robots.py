"""docs/robots.md's examples are what the loaders accept: its robot file gives the values its
table describes, its scenario runs against robot files of the three robots it names, and its lab
steps parse to the deaths, restarts, partition and heal it shows."""

from __future__ import annotations

from pathlib import Path

import pytest

from sdrpeer.monitor.scenario import Scenario
from sdrpeer.monitor.virtual import RobotFile

DOC = Path(__file__).resolve().parents[1] / "docs" / "robots.md"


def yaml_blocks() -> list[str]:
    text = DOC.read_text()
    return [part.split("```", 1)[0] for part in text.split("```yaml\n")[1:]]


def test_the_robot_file_example_loads_as_documented() -> None:
    robot = RobotFile.parse(yaml_blocks()[0], "docs/robots.md")
    assert (robot.name, robot.memory, robot.cpus, robot.priority) == ("robot-1", 4 * 10**9, 4, 10)
    assert robot.battery == 80.0
    assert robot.drain == pytest.approx(2 / 60)  # %/min in, %/s kept
    assert (robot.position, robot.rssi, robot.rssi_noise) == ((0.0, 0.0), -47.0, 1.5)


def test_the_scenario_example_runs_as_documented() -> None:
    files = [RobotFile(f"robot-{k}", 4 * 10**9, position=(0.0, 0.0), rssi=-47.0) for k in (1, 2, 3)]
    scenario = Scenario.parse(yaml_blocks()[1], "docs/robots.md", files)
    assert scenario.robots() == {"robot-1", "robot-2", "robot-3"}
    assert scenario.value_at("robot-1", "rssi", 109.5) == pytest.approx(-51.0)  # half way
    walked = 0.5 * 5.0  # 5 s at 0.5 m/s towards (5, 3), whose length is sqrt(34)
    expected = (walked * 5 / 34**0.5, walked * 3 / 34**0.5)
    assert scenario.value_at("robot-3", "pos", 25.0) == pytest.approx(expected)
    assert scenario.end() == pytest.approx(112.0)


def test_the_lab_steps_example_loads_as_documented() -> None:
    scenario = Scenario.parse(yaml_blocks()[2], "docs/robots.md")
    steps = [(s.at, s.kind, s.robot, s.values) for s in scenario.lab_steps()]
    assert steps == [
        (60.0, "agent", "robot-1", {"agent": "kill"}),
        (90.0, "agent", "robot-1", {"agent": "restart"}),
        (100.0, "agent", "robot-3", {"agent": "stop"}),
        (120.0, "partition", "", {"groups": (("robot-1", "robot-2"), ("robot-4", "robot-5"))}),
        (150.0, "heal", "", {}),
    ]
    assert scenario.changes_for("robot-4", 39.0, 40.0) == {"drain": pytest.approx(1.0)}
