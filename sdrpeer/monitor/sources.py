"""Real metric sources of the robot the agent runs on: psutil, cgroups, /sys and /proc.

How it works: `HostMetrics.sample(now)` reads each source once and returns a `Metrics`.
- cpu: `psutil.cpu_percent(None)` — the system-wide % since the previous call (non-blocking;
  the constructor primes it, so the first sample covers the time since construction).
- memory, cgroup-aware: the agent may run in a container whose memory limit is below the host's
  RAM. Every cgroup on the path from this process's cgroup (read from /proc/self/cgroup) up to
  the root is checked, v2 (`memory.max`, `memory.current`) and v1 (`memory/memory.limit_in_bytes`,
  `memory.usage_in_bytes`); the tightest limit below host RAM wins and is reported as total,
  with free = limit - (usage - inactive file cache from memory.stat). Otherwise psutil's
  total/available.
- battery: `psutil.sensors_battery()`, else the first `/sys/class/power_supply/*` of type
  Battery (its `capacity`); None when the robot has none.
- RSSI: the signal level of the first interface in `/proc/net/wireless` (dBm); None if absent.
All file reads go through `root` and the psutil calls are injectable, so tests feed fake trees.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path, PurePosixPath

import psutil

from sdrpeer.record.robot import Metrics

CGROUP = PurePosixPath("sys/fs/cgroup")


def _read(path: Path) -> str | None:
    """A small file's stripped text, or None if it cannot be read."""
    try:
        return path.read_text(encoding="ascii", errors="replace").strip()
    except OSError:
        return None


def _read_int(path: Path) -> int | None:
    """A file holding one integer, or None (missing, `max`, garbage)."""
    text = _read(path)
    try:
        return int(text) if text is not None else None
    except ValueError:
        return None


def _stat(path: Path, *keys: str) -> int:
    """The first of `keys` found in a cgroup memory.stat file, else 0."""
    text = _read(path) or ""
    values = dict(line.split(None, 1) for line in text.splitlines() if " " in line)
    for key in keys:
        if key in values and values[key].strip().isdigit():
            return int(values[key])
    return 0


def _cgroup_paths(root: Path) -> tuple[list[PurePosixPath], list[PurePosixPath]]:
    """This process's v2 and v1-memory cgroup paths and all their ancestors (leaf first)."""
    v2: list[PurePosixPath] = []
    v1: list[PurePosixPath] = []
    for line in (_read(root / "proc/self/cgroup") or "").splitlines():
        parts = line.split(":", 2)
        if len(parts) != 3 or not parts[2].startswith("/"):
            continue
        path = PurePosixPath(parts[2])
        chain = [path, *path.parents]
        if parts[0] == "0" and parts[1] == "":
            v2 = chain
        elif "memory" in parts[1].split(","):
            v1 = chain
    root_path = PurePosixPath("/")
    return (v2 or [root_path]), (v1 or [root_path])


def cgroup_memory(root: Path = Path("/")) -> tuple[int, int | None] | None:
    """(tightest cgroup memory limit, its usage minus inactive file cache) or None if unlimited."""
    candidates: list[tuple[int, int | None]] = []
    v2, v1 = _cgroup_paths(root)
    for p in v2:
        d = root / CGROUP / p.relative_to("/")
        limit = _read_int(d / "memory.max")
        if limit is not None:
            usage = _read_int(d / "memory.current")
            inactive = _stat(d / "memory.stat", "inactive_file")
            candidates.append((limit, None if usage is None else usage - inactive))
    for p in v1:
        d = root / CGROUP / "memory" / p.relative_to("/")
        limit = _read_int(d / "memory.limit_in_bytes")
        if limit is not None:
            usage = _read_int(d / "memory.usage_in_bytes")
            inactive = _stat(d / "memory.stat", "total_inactive_file", "inactive_file")
            candidates.append((limit, None if usage is None else usage - inactive))
    return min(candidates, key=lambda c: c[0]) if candidates else None


def memory(root: Path, host_total: int, host_available: int) -> tuple[int, int]:
    """(total, free) bytes: the cgroup limit if it is below host RAM, else the host's figures."""
    cg = cgroup_memory(root)
    if cg is None or cg[0] >= host_total:
        return host_total, host_available
    limit, used = cg
    free = min(limit, host_available) if used is None else limit - max(0, used)
    return limit, max(0, min(limit, free))


def battery_from_sysfs(root: Path = Path("/")) -> float | None:
    """Capacity % of the first present power supply of type Battery, or None."""
    supplies = root / "sys/class/power_supply"
    try:
        entries = sorted(supplies.iterdir())
    except OSError:
        return None
    for d in entries:
        if _read(d / "type") != "Battery" or _read(d / "present") == "0":
            continue
        capacity = _read_int(d / "capacity")
        if capacity is not None:
            return float(min(100, max(0, capacity)))
    return None


def rssi_from_proc(root: Path = Path("/")) -> float | None:
    """Signal level (dBm) of the first interface listed in /proc/net/wireless, or None."""
    text = _read(root / "proc/net/wireless")
    for line in (text or "").splitlines()[2:]:
        _, sep, rest = line.partition(":")
        fields = rest.split()
        if not sep or len(fields) < 3:
            continue
        try:
            level = float(fields[2].rstrip("."))
        except ValueError:
            return None
        if level > 0:  # old drivers report dBm as an unsigned byte (e.g. 200 = -56 dBm)
            level -= 256
        return None if level == 0 or level <= -256 else level
    return None


def _psutil_battery() -> float | None:
    """psutil's battery percent, where the platform has one."""
    sensors = getattr(psutil, "sensors_battery", None)
    try:
        battery = sensors() if sensors is not None else None
    except (OSError, RuntimeError):
        return None
    return None if battery is None else float(battery.percent)


def _psutil_memory() -> tuple[int, int]:
    """Host RAM (total, available) from psutil."""
    vm = psutil.virtual_memory()
    return int(vm.total), int(vm.available)


def _psutil_cpu() -> float:
    """System-wide cpu % since the previous call."""
    return float(psutil.cpu_percent(None))


class HostMetrics:
    """Samples the real robot: cpu, cgroup-aware memory, battery, RSSI, position."""

    def __init__(
        self,
        root: Path = Path("/"),
        *,
        cpu: Callable[[], float] = _psutil_cpu,
        host_memory: Callable[[], tuple[int, int]] = _psutil_memory,
        battery: Callable[[], float | None] = _psutil_battery,
        position: Callable[[], tuple[float, float] | None] = lambda: None,
    ) -> None:
        self.root = root
        self._cpu = cpu
        self._host_memory = host_memory
        self._battery = battery
        self._position = position
        self._cpu()  # prime: psutil's first non-blocking reading is meaningless

    def sample(self, now: float) -> Metrics:
        """Read every source once (`now` is accepted for symmetry with virtual robots)."""
        total, free = memory(self.root, *self._host_memory())
        battery = self._battery()
        return Metrics(
            cpu_pct=self._cpu(),
            mem_total=total,
            mem_free=free,
            battery_pct=battery if battery is not None else battery_from_sysfs(self.root),
            rssi_dbm=rssi_from_proc(self.root),
            pos=self._position(),
        )
