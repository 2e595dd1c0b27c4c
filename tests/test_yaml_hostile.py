"""Hostile YAML given to every loader (system, robot, scenario, agent config): each is a
`file:line` error in the project's words, fast and small, never a traceback (issue 14: an alias
bomb took 1.8 GB and no answer in 150 s; tags, NUL bytes, recursive aliases and deep nesting
gave Python tracebacks)."""

from __future__ import annotations

import resource
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from sdrpeer.config import load_agent_config
from sdrpeer.errors import ConfigError
from sdrpeer.monitor.scenario import Scenario
from sdrpeer.monitor.virtual import RobotFile
from sdrpeer.system.loader import load_system
from sdrpeer.yamlfile import MAX_BYTES


def _bomb(levels: int = 12) -> str:
    """One value nine-to-the-`levels` strings big once expanded (a few hundred bytes)."""
    items = ['&l0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, levels):
        items.append(f"&l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]")
    return "KEY: [" + ", ".join(items) + "]\n"


HOSTILE: dict[str, tuple[str, str]] = {
    # name: (text, what the message says); KEY is a field each loader reads first
    "alias bomb": (_bomb(), "values once aliases expand"),
    "recursive alias": ("KEY: &a [*a]\n", "an alias refers to its own anchor"),
    "python tag": ('KEY: !!python/object/apply:os.system ["true"]\n', "is not allowed"),
    "custom tag": ("KEY: !secret x\n", "is not allowed"),
    "NUL byte": ("KEY: r1\x00\n", "is not allowed"),
    "control character": ("KEY: r1\x07\n", "is not allowed"),
    "deep nesting": ("KEY: " + "[" * 5000 + "]" * 5000 + "\n", "nested deeper than"),
    "deep mappings": ("KEY: " + "{a: " * 200 + "1" + "}" * 200 + "\n", "nested deeper than"),
    "too big": ("# " + "x" * (MAX_BYTES + 10) + "\nKEY: r1\n", "larger than"),
    "unhashable key": ("KEY: {[a, b]: 1}\n", ""),  # refused where the loader first looks
}


def _system(path: Path) -> object:
    return load_system(path)


def _robot(path: Path) -> object:
    return RobotFile.load(path)


def _scenario(path: Path) -> object:
    return Scenario.load(path)


def _config(path: Path) -> object:
    return load_agent_config(path)


LOADERS: dict[str, tuple[Callable[[Path], object], str]] = {
    "system": (_system, "name"),
    "robot": (_robot, "name"),
    "scenario": (_scenario, "description"),
    "agent config": (_config, "name"),
}


@pytest.mark.parametrize("loader", LOADERS)
@pytest.mark.parametrize("case", HOSTILE)
def test_hostile_yaml_is_a_file_line_error(tmp_path: Path, loader: str, case: str) -> None:
    text, says = HOSTILE[case]
    load, key = LOADERS[loader]
    path = tmp_path / "hostile.yaml"
    path.write_text(text.replace("KEY", key), encoding="utf-8")
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    began = time.process_time()
    with pytest.raises(ConfigError) as info:
        load(path)
    took = time.process_time() - began
    message = str(info.value)
    assert message.startswith(str(path)), message
    assert says in message, message
    assert "Traceback" not in message
    assert took < 5.0, f"{took:.1f} s of CPU"  # the bomb took minutes before
    grew_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_before
    assert grew_kib < 200_000, f"peak RSS grew {grew_kib} KiB"


def test_a_file_that_is_not_utf8_names_itself(tmp_path: Path) -> None:
    path = tmp_path / "r1.yaml"
    path.write_bytes(b"name: r\xff1\nmemory: 4GB\n")
    with pytest.raises(ConfigError, match=r"r1\.yaml: cannot read: not UTF-8 text \(byte 7\)"):
        RobotFile.load(path)


def test_a_plain_file_with_anchors_and_merge_keys_still_loads(tmp_path: Path) -> None:
    path = tmp_path / "r1.yaml"
    path.write_text("name: &n r1\nmemory: 4GB\nposition: &p [1, 2]\n")
    robot = RobotFile.load(path)
    assert (robot.name, robot.position) == ("r1", (1.0, 2.0))
    system = tmp_path / "s.yaml"
    system.write_text(
        "name: s\ncomponents:\n"
        "  - &cam {name: Cam, target: 'components.camera:Camera', params: {reserve_mb: 0}}\n"
        "  - {<<: *cam, name: Cam2}\n"
    )
    assert [c.name for c in load_system(system).components] == ["Cam", "Cam2"]
