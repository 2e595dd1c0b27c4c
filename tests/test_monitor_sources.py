"""Real sources, fed fake /proc and /sys trees: cgroup v1/v2/unlimited, battery, RSSI."""

from __future__ import annotations

from pathlib import Path

import pytest

from sdrpeer.monitor import sources
from sdrpeer.monitor.sources import HostMetrics

GB = 1_000_000_000
HOST = (16 * GB, 12 * GB)  # fake host RAM: total, available


def write(root: Path, rel: str, text: str) -> None:
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def host(root: Path, battery: float | None = None) -> HostMetrics:
    return HostMetrics(
        root,
        cpu=lambda: 42.5,
        host_memory=lambda: HOST,
        battery=lambda: battery,
        position=lambda: (1.0, 2.0),
    )


def test_no_cgroup_files_uses_host_memory(tmp_path: Path) -> None:
    m = host(tmp_path).sample(0.0)
    assert (m.mem_total, m.mem_free) == HOST
    assert (m.cpu_pct, m.battery_pct, m.rssi_dbm, m.pos) == (42.5, None, None, (1.0, 2.0))


def test_cgroup_v2_limit(tmp_path: Path) -> None:
    write(tmp_path, "proc/self/cgroup", "0::/\n")
    write(tmp_path, "sys/fs/cgroup/memory.max", f"{2 * GB}\n")
    write(tmp_path, "sys/fs/cgroup/memory.current", f"{GB}\n")
    write(tmp_path, "sys/fs/cgroup/memory.stat", "anon 1\ninactive_file 300000000\nfile 5\n")
    m = host(tmp_path).sample(0.0)
    assert (m.mem_total, m.mem_free) == (2 * GB, 2 * GB - (GB - 300_000_000))


def test_cgroup_v2_max_is_unlimited(tmp_path: Path) -> None:
    write(tmp_path, "proc/self/cgroup", "0::/\n")
    write(tmp_path, "sys/fs/cgroup/memory.max", "max\n")
    write(tmp_path, "sys/fs/cgroup/memory.current", f"{GB}\n")
    assert host(tmp_path).sample(0.0).mem_total == HOST[0]


def test_cgroup_v2_nested_takes_the_tightest_ancestor(tmp_path: Path) -> None:
    write(tmp_path, "proc/self/cgroup", "0::/robots/r1/agent\n")
    write(tmp_path, "sys/fs/cgroup/robots/r1/agent/memory.max", "max\n")
    write(tmp_path, "sys/fs/cgroup/robots/r1/memory.max", f"{3 * GB}\n")
    write(tmp_path, "sys/fs/cgroup/robots/r1/memory.current", f"{GB}\n")
    write(tmp_path, "sys/fs/cgroup/robots/memory.max", f"{8 * GB}\n")
    m = host(tmp_path).sample(0.0)
    assert (m.mem_total, m.mem_free) == (3 * GB, 2 * GB)


def test_cgroup_v1_limit_and_total_inactive_file(tmp_path: Path) -> None:
    write(tmp_path, "proc/self/cgroup", "5:cpu,cpuacct:/\n4:memory:/\n0::/\n")
    base = "sys/fs/cgroup/memory/"
    write(tmp_path, base + "memory.limit_in_bytes", f"{4 * GB}\n")
    write(tmp_path, base + "memory.usage_in_bytes", f"{3 * GB}\n")
    write(tmp_path, base + "memory.stat", f"inactive_file 1\ntotal_inactive_file {GB}\n")
    m = host(tmp_path).sample(0.0)
    assert (m.mem_total, m.mem_free) == (4 * GB, 2 * GB)


def test_cgroup_v1_unlimited_is_the_huge_number(tmp_path: Path) -> None:
    write(tmp_path, "proc/self/cgroup", "4:memory:/docker/abc\n")
    write(tmp_path, "sys/fs/cgroup/memory/memory.limit_in_bytes", "9223372036854771712\n")
    write(tmp_path, "sys/fs/cgroup/memory/memory.usage_in_bytes", f"{GB}\n")
    m = host(tmp_path).sample(0.0)
    assert (m.mem_total, m.mem_free) == HOST


def test_cgroup_without_usage_caps_host_available(tmp_path: Path) -> None:
    write(tmp_path, "sys/fs/cgroup/memory.max", f"{GB}\n")
    assert sources.memory(tmp_path, 16 * GB, 12 * GB) == (GB, GB)
    assert sources.memory(tmp_path, 16 * GB, GB // 2) == (GB, GB // 2)


def test_cgroup_over_limit_reports_zero_free(tmp_path: Path) -> None:
    write(tmp_path, "sys/fs/cgroup/memory.max", f"{GB}\n")
    write(tmp_path, "sys/fs/cgroup/memory.current", f"{2 * GB}\n")
    assert sources.memory(tmp_path, 16 * GB, 12 * GB) == (GB, 0)


def test_battery_from_psutil_wins(tmp_path: Path) -> None:
    write(tmp_path, "sys/class/power_supply/BAT0/type", "Battery\n")
    write(tmp_path, "sys/class/power_supply/BAT0/capacity", "40\n")
    assert host(tmp_path, battery=77.0).sample(0.0).battery_pct == 77.0
    assert host(tmp_path, battery=None).sample(0.0).battery_pct == 40.0


def test_battery_from_sysfs_skips_mains_and_absent(tmp_path: Path) -> None:
    write(tmp_path, "sys/class/power_supply/AC/type", "Mains\n")
    write(tmp_path, "sys/class/power_supply/AC/capacity", "100\n")
    assert sources.battery_from_sysfs(tmp_path) is None
    write(tmp_path, "sys/class/power_supply/BAT0/type", "Battery\n")
    write(tmp_path, "sys/class/power_supply/BAT0/present", "0\n")
    write(tmp_path, "sys/class/power_supply/BAT0/capacity", "10\n")
    write(tmp_path, "sys/class/power_supply/BAT1/type", "Battery\n")
    write(tmp_path, "sys/class/power_supply/BAT1/capacity", "63\n")
    assert sources.battery_from_sysfs(tmp_path) == 63.0


WIRELESS = """\
Inter-| sta-|   Quality        |   Discarded packets               | Missed | WE
 face | tus | link level noise |  nwid  crypt   frag  retry   misc | beacon | 22
{lines}"""


@pytest.mark.parametrize(
    ("lines", "expected"),
    [
        ("wlan0: 0000   54.  -56.  -256        0      0      0      0      0        0\n", -56.0),
        (
            "wlan0: 0000   40.  -70.  -256   0 0 0 0 0 0\nwlan1: 0000   60.  -40.  -256\n",
            -70.0,
        ),
        ("wlan0: 0000   54.  200.  0   0 0 0 0 0 0\n", -56.0),  # old unsigned-byte dBm
        ("wlan0: 0000   0.  0.  0   0 0 0 0 0 0\n", None),  # no signal information
        ("", None),
    ],
)
def test_rssi_from_proc_net_wireless(tmp_path: Path, lines: str, expected: float | None) -> None:
    write(tmp_path, "proc/net/wireless", WIRELESS.format(lines=lines))
    assert sources.rssi_from_proc(tmp_path) == expected


def test_rssi_absent(tmp_path: Path) -> None:
    assert sources.rssi_from_proc(tmp_path) is None


def test_real_host_sample_is_sane() -> None:
    m = HostMetrics().sample(0.0)
    assert 0.0 <= m.cpu_pct <= 100.0
    assert 0 <= m.mem_free <= m.mem_total
