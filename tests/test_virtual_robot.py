"""Virtual robots: robot files with located errors, measured memory, drain, noise, live set()."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from sdrpeer.cli.common import parse_assignment
from sdrpeer.errors import ConfigError
from sdrpeer.monitor.virtual import RobotFile, VirtualRobot

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "robots"

GOOD = """\
name: r1
memory: 4GB
cpus: 4
battery: 100%
drain: 0.5%/min
position: [3, 4.5]
rssi: -45dBm
priority: 2
"""


def test_robot_file_fields() -> None:
    f = RobotFile.parse(GOOD, "robots/r1.yaml")
    assert f == RobotFile(
        name="r1",
        memory=4_000_000_000,
        cpus=4,
        battery=100.0,
        drain=0.5 / 60,
        position=(3.0, 4.5),
        rssi=-45.0,
        rssi_noise=0.0,
        priority=2,
    )


def test_defaults() -> None:
    f = RobotFile.parse("name: r\nmemory: 512MiB\n")
    assert (f.cpus, f.battery, f.drain, f.position, f.rssi, f.priority) == (
        1,
        None,
        0.0,
        None,
        None,
        0,
    )


def test_example_robot_files_load() -> None:
    files = {p.stem: RobotFile.load(p) for p in sorted(EXAMPLES.glob("robot-*.yaml"))}
    assert sorted(files) == ["robot-1", "robot-2", "robot-3"]
    assert [f.memory for f in files.values()] == [2_000_000_000] * 3  # Fig. 3 under Table V
    assert [f.battery for f in files.values()] == [100.0, 90.0, 95.0]
    assert all(f.name == stem for stem, f in files.items())


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "name: r1\ncpus: 4\nbattery: 100%\nmemory: lots\n",
            "robots/r1.yaml:4: field 'memory': expected a size such as 500MB, got 'lots'",
        ),
        (
            "name: r1\nmemory: 4GB\ncolour: red\n",
            "robots/r1.yaml:3: field 'colour': unknown field (known: name, memory, cpus,",
        ),
        ("name: r1\ncpus: 2\n", "robots/r1.yaml:1: field 'memory': missing (required)"),
        (
            "name: r1\nmemory: 4GB\nbattery: 120%\n",
            "robots/r1.yaml:3: field 'battery': '120%' is out of range (0% to 100%)",
        ),
        (
            "name: r1\nmemory: 4GB\nposition: [1]\n",
            "robots/r1.yaml:3: field 'position': expected a position such as [3, 4.5], got [1]",
        ),
        (
            "name: r1\nmemory: 4GB\nrssi: -45dB\n",
            "robots/r1.yaml:3: field 'rssi': expected a power such as -52.5dBm, got '-45dB'",
        ),
        (
            "name: r1\nmemory: 4GB\ndrain: 1%\n",
            "robots/r1.yaml:3: field 'drain': expected a rate such as 2%/min, got '1%'",
        ),
        (
            "name: r1\nmemory: 4GB\ncpus: 0\n",
            "robots/r1.yaml:3: field 'cpus': 0 is out of range (1 to 4096)",
        ),
        (
            "name: r 1\nmemory: 4GB\n",
            "robots/r1.yaml:1: field 'name': expected a name such as robot-1, got 'r 1'",
        ),
        (
            "name: r1\nmemory: 4GB\nmemory: 2GB\n",
            "robots/r1.yaml:3: field 'memory': given twice (first at line 2)",
        ),
        (  # the hostile values: each refused, naming the field and the range
            "name: r1\nmemory: 4GB\nposition: [1e308, -1e308]\n",
            "robots/r1.yaml:3: field 'position': '1e308' is out of range (-10000km to 10000km)",
        ),
        (
            "name: r1\nmemory: 4GB\npriority: -99999999999999999999\n",
            "robots/r1.yaml:3: field 'priority': -99999999999999999999 is out of range",
        ),
        (
            "name: r1\nmemory: 4GB\nrssi: +50dBm\n",
            "robots/r1.yaml:3: field 'rssi': '+50dBm' is out of range (-150dBm to 0dBm)",
        ),
        (
            "name: r1\nmemory: 1000000TB\n",
            "robots/r1.yaml:2: field 'memory': '1000000TB' is out of range (1MB to 1PiB)",
        ),
        (
            "name: r1\nmemory: 4GB\ndrain: -600%/min\n",
            "robots/r1.yaml:3: field 'drain': '-600%/min' is out of range (-100%/min to 100%/min",
        ),
        ("- r1\n", "robots/r1.yaml:1: expected a mapping with name, memory"),
        ("", "robots/r1.yaml: expected a mapping"),
        ("name: [r1\n", "robots/r1.yaml:2: not valid YAML"),
    ],
)
def test_robot_file_errors_name_file_line_field(text: str, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        RobotFile.parse(text, "robots/r1.yaml")
    assert str(info.value).startswith(message)


def test_load_names_the_path(tmp_path: Path) -> None:
    path = tmp_path / "r.yaml"
    path.write_text("name: r\nmemory: 4GB\n\n\nrssi: loud\n")
    with pytest.raises(ConfigError, match=r"r\.yaml:5: field 'rssi': expected a power"):
        RobotFile.load(path)
    with pytest.raises(ConfigError, match=r"missing\.yaml: cannot read"):
        RobotFile.load(tmp_path / "missing.yaml")


class Load:
    """A fake measurement of the hosted processes."""

    def __init__(self) -> None:
        self.cpu = 0.0
        self.rss = 0

    def __call__(self) -> tuple[float, int]:
        return self.cpu, self.rss


def robot(text: str = GOOD) -> tuple[VirtualRobot, Load]:
    load = Load()
    return VirtualRobot(RobotFile.parse(text), load, start=100.0), load


def test_free_memory_is_capacity_minus_measured_rss() -> None:
    r, load = robot()
    assert r.sample(100.0).mem_free == 4_000_000_000
    load.rss = 1_500_000_000
    m = r.sample(101.0)
    assert (m.mem_total, m.mem_free) == (4_000_000_000, 2_500_000_000)
    load.rss = 5_000_000_000
    assert r.sample(102.0).mem_free == 0


def test_cpu_is_measured_load_over_cpus() -> None:
    r, load = robot()
    load.cpu = 150.0  # psutil process units: 1.5 cores busy
    assert r.sample(100.0).cpu_pct == 37.5
    load.cpu = 900.0
    assert r.sample(100.0).cpu_pct == 100.0


def test_battery_drains_linearly_and_clamps_at_zero() -> None:
    r, _ = robot()
    assert r.sample(100.0).battery_pct == 100.0
    assert r.sample(160.0).battery_pct == pytest.approx(99.5)
    assert r.sample(100.0 + 60 * 60).battery_pct == pytest.approx(70.0)
    assert r.sample(100.0 + 200 * 60).battery_pct == 0.0
    assert r.sample(100.0 + 999 * 60).battery_pct == 0.0


def test_start_defaults_to_first_sample() -> None:
    r = VirtualRobot(RobotFile.parse(GOOD), Load())
    assert r.sample(5000.0).battery_pct == 100.0
    assert r.sample(5120.0).battery_pct == pytest.approx(99.0)


def test_no_battery_no_rssi() -> None:
    r = VirtualRobot(RobotFile.parse("name: r\nmemory: 1GB\n"), Load())
    m = r.sample(0.0)
    assert (m.battery_pct, m.rssi_dbm, m.pos) == (None, None, None)


def test_rssi_noise_is_deterministic_and_bounded() -> None:
    text = GOOD + "rssi_noise: 1dB\n"
    a, _ = robot(text)
    b, _ = robot(text)
    values = [a.sample(100.0 + t / 10).rssi_dbm for t in range(200)]
    assert values == [b.sample(100.0 + t / 10).rssi_dbm for t in range(200)]
    assert all(v is not None and -48.0 <= v <= -42.0 for v in values)
    assert len(set(values)) > 100  # really noisy
    mean = sum(v for v in values if v is not None) / len(values)
    assert mean == pytest.approx(-45.0, abs=0.3)


def test_set_changes_live_and_reanchors_the_battery() -> None:
    r, _ = robot()
    r.set(160.0, {"drain": "6%/min"})  # 99.5 % at 160 s, then 0.1 %/s
    assert r.sample(170.0).battery_pct == pytest.approx(98.5)
    r.set(200.0, {"battery": 50, "rssi": "-55dBm", "pos": [1, "-2m"], "memory": "2GB"})
    m = r.sample(210.0)
    assert m.battery_pct == pytest.approx(49.0)
    assert (m.rssi_dbm, m.pos, m.mem_total) == (-55.0, (1.0, -2.0), 2_000_000_000)


def test_set_is_all_or_nothing_and_names_the_field() -> None:
    r, _ = robot()
    with pytest.raises(
        ConfigError, match=r"^robot r1: field 'rssi': expected a power such as -52\.5dBm"
    ):
        r.set(100.0, {"pos": [9, 9], "rssi": "weak"})
    assert r.sample(100.0).pos == (3.0, 4.5)
    with pytest.raises(ConfigError, match=r"field 'cpu_load': cannot be changed \(settable: "):
        r.set(100.0, {"cpu_load": 50})


@pytest.mark.parametrize("written", ["50%", "50 %", "50", 50, 50.0])
def test_a_battery_reads_the_same_from_the_api_the_cli_and_the_robot_file(written: object) -> None:
    """`POST /v1/robot {"battery": "50%"}` takes the unit string as the robot file and `sdrpeer
    robot set robot-1 battery=50%` do (a plain number is percent): 50 % whichever way."""
    from_api, _ = robot()
    from_api.set(100.0, {"battery": written})  # the API hands its JSON body to set()
    _, from_cli_value = parse_assignment(f"battery={written}")
    from_cli, _ = robot()
    from_cli.set(100.0, {"battery": from_cli_value})
    from_file, _ = robot(GOOD.replace("battery: 100%", f"battery: {written}"))
    assert [r.sample(100.0).battery_pct for r in (from_api, from_cli, from_file)] == [50.0] * 3


@pytest.mark.parametrize("written", ["fifty", "50 percent", "50%%", True, None, [50]])
def test_a_battery_in_no_known_form_is_refused_naming_the_field(written: object) -> None:
    r, _ = robot()
    with pytest.raises(
        ConfigError, match=r"^robot r1: field 'battery': expected a percentage such as 80%, got "
    ):
        r.set(100.0, {"battery": written, "rssi": "-60dBm"})
    assert r.sample(100.0).battery_pct == 100.0
    assert r.sample(100.0).rssi_dbm == -45.0  # all or nothing


def test_a_robot_name_longer_than_the_gossip_wire_carries_is_refused() -> None:
    long = "r" * 256
    with pytest.raises(
        ConfigError,
        match=re.escape(
            f"r.yaml:1: field 'name': a robot name has at most 255 characters, "
            f"got '{'r' * 60}'... (256 characters)"
        ),
    ):
        RobotFile.parse(f"name: {long}\nmemory: 1GB\n", "r.yaml")
    assert RobotFile.parse(f"name: {'r' * 255}\nmemory: 1GB\n").name == "r" * 255
