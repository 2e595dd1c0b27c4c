"""Read what a system file needs from a profile written by `sdrpeer profile`
(sdrpeer.profiling.measure).

How it works: the profile is composed with `YamlFile`, so a broken profile is reported with its
own file and line. Only four things are taken: `target`, `cpu.mean_pct` (percent of one core),
`memory.peak_rss` (bytes) and `bytes_per_s` of every port whose `direction` is `out`. Other keys
are left alone (a profile carries host facts and params we do not need). Errors are raised as
`ProfileFileError` (a ValueError, so the loader reports them at the `profile:` line of the system
file).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from sdrpeer.errors import ConfigError, ProfileFileError, shown
from sdrpeer.system.values import MAX_RATE
from sdrpeer.yamlfile import YamlFile


@dataclass(frozen=True, slots=True)
class ProfileFigures:
    """The figures of one profile file."""

    path: str
    target: str | None
    cpu_pct: float
    mem_bytes: int
    out_bytes_per_s: dict[str, float]


def read_profile(path: Path, shown: str) -> ProfileFigures:
    """The figures of the profile at `path` (`shown` is how messages name it)."""
    try:
        is_file = path.is_file()
    except OSError as e:  # a name too long, a path through a file, ...
        raise ProfileFileError(f"cannot read profile file {shown[:200]!r}: {e.strerror}") from None
    if not is_file:
        raise ProfileFileError(f"no such profile file {shown[:200]!r}")
    try:
        f = YamlFile.read(path)
        f.name = shown
        return _figures(f, shown)
    except ConfigError as e:
        raise ProfileFileError(f"bad profile: {e}") from None


def _figures(f: YamlFile, shown: str) -> ProfileFigures:
    if not isinstance(f.root, yaml.MappingNode):
        f.fail(f.root, None, "a profile is a mapping (written by `sdrpeer profile`)")
    top = _children(f, f.root)
    cpu = f.mapping(top.get("cpu"), "cpu", ("mean_pct", "peak_pct", "samples"), ("mean_pct",))
    mem = f.mapping(
        top.get("memory"), "memory", ("peak_rss", "peak_rss_human", "mean_rss"), ("peak_rss",)
    )
    cpu_pct = f.parse(cpu["mean_pct"], "cpu.mean_pct", _non_negative)
    mem_bytes = f.parse(mem["peak_rss"], "memory.peak_rss", _non_negative)
    rates: dict[str, float] = {}
    ports = top.get("ports")
    if ports is not None:
        if not isinstance(ports, yaml.MappingNode):
            f.fail(ports, "ports", "expected a mapping of port -> {direction, bytes_per_s}")
        for port, node in _children(f, ports).items():
            where = f"ports.{port}"
            fields = f.mapping(
                node, where, ("direction", "frames_per_s", "bytes_per_s"), ("direction",)
            )
            if f.value(fields["direction"]) != "out":
                continue
            if "bytes_per_s" not in fields:
                f.fail(node, f"{where}.bytes_per_s", "missing (required for an out port)")
            rate = f.parse(fields["bytes_per_s"], f"{where}.bytes_per_s", _non_negative)
            if rate > MAX_RATE:
                f.fail(fields["bytes_per_s"], f"{where}.bytes_per_s", "absurdly high")
            rates[port] = rate
    target = f.value(top["target"]) if "target" in top else None
    return ProfileFigures(
        path=shown,
        target=target if isinstance(target, str) else None,
        cpu_pct=cpu_pct,
        mem_bytes=round(mem_bytes),
        out_bytes_per_s=rates,
    )


def _children(f: YamlFile, node: yaml.MappingNode) -> dict[str, yaml.Node]:
    return {str(f.value(k)): v for k, v in node.value}


def _non_negative(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"expected a number >= 0, got {shown(value)}")
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"expected a number >= 0, got {shown(value)}")
    return float(value)
