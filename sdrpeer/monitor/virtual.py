"""A virtual robot: one machine standing in for a fleet, with hardware facts from a robot file.

How it works: a `RobotFile` (YAML) gives the robot's *capacities and physics* — memory size,
cpu count, battery level and drain rate, position, RSSI. Everything the platform does on the
robot is *measured*: `VirtualRobot` calls `measure()` for the cpu % and RSS of the processes it
really hosts, so free memory = capacity - measured RSS and cpu % = measured cpu / cpus. Nothing
is invented except the physics: the battery drains linearly from its last anchor (start, or the
last `set`) and the RSSI is the set level plus optional noise that is a pure function of
(robot name, time), so a run can be repeated exactly. Time is always passed in.

Robot file fields: name (required), memory (required, e.g. 4GB), cpus (1), battery (none: mains
powered), drain (0%/s), position ([x, y] in metres; none = unknown), rssi (none = wired),
rssi_noise (0dB: standard deviation of a gaussian clipped at 3 sigma), priority (0).
"""

from __future__ import annotations

import random
import re
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sdrpeer import units
from sdrpeer.config import MAX_NAME
from sdrpeer.errors import ConfigError, shown
from sdrpeer.record.limits import check, check_int
from sdrpeer.record.robot import Metrics
from sdrpeer.yamlfile import YamlFile

NAME_RE = re.compile(r"[A-Za-z0-9_.-]+")


def parse_name(value: object) -> str:
    """A robot name: letters, digits, `_`, `.`, `-`."""
    if not isinstance(value, str) or not NAME_RE.fullmatch(value):
        raise ValueError(f"expected a name such as robot-1, got {shown(value)}")
    if len(value) > MAX_NAME:
        raise ValueError(f"a robot name has at most {MAX_NAME} characters, got {shown(value)}")
    return value


def parse_memory(value: object) -> int:
    """A memory capacity: a size from 1MB to 1PiB."""
    return round(check("memory", units.parse_size(value), value))


def parse_battery(value: object) -> float:
    """A battery level, 0..100 %."""
    return check("battery", units.parse_percent(value), value)


def parse_rssi(value: object) -> float:
    """A signal level, -150..0 dBm."""
    return check("rssi", units.parse_power(value), value)


def parse_drain(value: object) -> float:
    """A battery drain in %/s (negative: charging), at most 100 %/min either way."""
    return check("drain", units.parse_rate(value), value)


def _coord(c: object) -> float:
    """One coordinate in metres: a number or a distance such as -2.5m, within 10,000 km."""
    if isinstance(c, int | float) and not isinstance(c, bool):
        out = float(c)
    elif isinstance(c, str) and c.strip().startswith("-"):
        out = -units.parse_distance(c.strip()[1:])
    else:
        out = units.parse_distance(c)
    return check("coord", out, c)


def parse_position(value: object) -> tuple[float, float]:
    """[x, y] in metres (numbers or distances such as 3m; negative coordinates allowed)."""
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ValueError(f"expected a position such as [3, 4.5], got {shown(value)}")
    return (_coord(value[0]), _coord(value[1]))


def _integer(name: str, example: str) -> Callable[[object], int]:
    return lambda value: check_int(name, value, example)


def _noise(value: object) -> float:
    """A noise level in dB, 0..30."""
    return check("rssi_noise", units.parse_db(value), value)


def _skew(value: object) -> float:
    """A clock error within a day either way."""
    return check("clock_skew", units.parse_offset(value), value)


SETTABLE: dict[str, Callable[[object], Any]] = {
    "battery": parse_battery,
    "drain": parse_drain,
    "memory": parse_memory,
    "pos": parse_position,
    "rssi": parse_rssi,
}
"""What `VirtualRobot.set` (and a scenario's `set`) may change, and how each value is parsed."""

_FILE_FIELDS: dict[str, Callable[[object], Any]] = {
    "name": parse_name,
    "memory": parse_memory,
    "cpus": _integer("cpus", "4"),
    "battery": parse_battery,
    "drain": parse_drain,
    "position": parse_position,
    "rssi": parse_rssi,
    "rssi_noise": _noise,
    "priority": _integer("priority", "0"),
    "clock_skew": _skew,
}


@dataclass(frozen=True, slots=True)
class RobotFile:
    """A virtual robot's hardware facts (sizes in bytes, drain in %/s, position in metres)."""

    name: str
    memory: int
    cpus: int = 1
    battery: float | None = None
    drain: float = 0.0
    position: tuple[float, float] | None = None
    rssi: float | None = None
    rssi_noise: float = 0.0
    priority: int = 0
    clock_skew: float = 0.0
    """Seconds this robot's clock is off true time (its gossip sees time.time() + skew)."""

    def wall(self) -> float:
        """This robot's wall clock: true time plus `clock_skew`."""
        return time.time() + self.clock_skew

    @classmethod
    def load(cls, path: Path | str) -> RobotFile:
        """Read and validate a robot file; errors name file, line and field."""
        return cls._from(YamlFile.read(path, ConfigError))

    @classmethod
    def parse(cls, text: str, filename: str = "<robot file>") -> RobotFile:
        """Validate robot-file text; `filename` is used in error messages."""
        return cls._from(YamlFile(text, filename, ConfigError))

    @classmethod
    def _from(cls, doc: YamlFile) -> RobotFile:
        """Build from a composed document."""
        nodes = doc.mapping(doc.root, None, _FILE_FIELDS, required=("name", "memory"))
        values = {key: doc.parse(node, key, _FILE_FIELDS[key]) for key, node in nodes.items()}
        return cls(**values)


class VirtualRobot:
    """Samples a robot file's facts plus the measured load of the processes it hosts."""

    def __init__(
        self,
        robot_file: RobotFile,
        measure: Callable[[], tuple[float, int]],
        start: float | None = None,
    ) -> None:
        self.file = robot_file
        self._measure = measure
        self.memory = robot_file.memory
        self.rssi = robot_file.rssi
        self.pos = robot_file.position
        self.drain = robot_file.drain
        self._battery = robot_file.battery
        self._anchor = start
        """Time at which the battery was `_battery` (None until the first sample or set)."""

    @property
    def name(self) -> str:
        """The robot's name."""
        return self.file.name

    def battery_at(self, now: float) -> float | None:
        """Battery level at `now`: linear drain from the last anchor, clamped to 0..100 %."""
        if self._battery is None:
            return None
        if self._anchor is None:
            self._anchor = now
        level = self._battery - self.drain * (now - self._anchor)
        return min(100.0, max(0.0, level))

    def rssi_at(self, now: float) -> float | None:
        """RSSI at `now`: the set level plus the robot's deterministic noise."""
        if self.rssi is None:
            return None
        sigma = self.file.rssi_noise
        if sigma <= 0:
            return self.rssi
        rng = random.Random(f"{self.name}:{round(now * 1000)}")
        return self.rssi + max(-3 * sigma, min(3 * sigma, rng.gauss(0.0, sigma)))

    def sample(self, now: float) -> Metrics:
        """The robot's metrics at `now` (cpu and free memory measured, the rest simulated)."""
        cpu, rss = self._measure()
        return Metrics(
            cpu_pct=min(100.0, max(0.0, cpu / self.file.cpus)),
            mem_total=self.memory,
            mem_free=max(0, self.memory - rss),
            battery_pct=self.battery_at(now),
            rssi_dbm=self.rssi_at(now),
            pos=self.pos,
        )

    def set(self, now: float, changes: Mapping[str, object]) -> None:
        """Apply live changes (battery, drain, memory, pos, rssi); all or nothing."""
        parsed: dict[str, Any] = {}
        for key, value in changes.items():
            if key not in SETTABLE:
                settable = ", ".join(SETTABLE)
                raise ConfigError(
                    f"robot {self.name}: field {key!r}: cannot be changed (settable: {settable})"
                )
            try:
                parsed[key] = SETTABLE[key](value)
            except ValueError as e:
                raise ConfigError(f"robot {self.name}: field {key!r}: {e}") from None
        if "drain" in parsed or "battery" in parsed:
            # Re-anchor so the old rate applies up to now and the new one from now on.
            self._battery = parsed.get("battery", self.battery_at(now))
            self._anchor = now
        self.drain = parsed.get("drain", self.drain)
        self.memory = parsed.get("memory", self.memory)
        self.pos = parsed.get("pos", self.pos)
        self.rssi = parsed.get("rssi", self.rssi)
