"""Whether ROS 2 is installed beside sdrpeer, and the environment a ROS 2 process needs (pure but
for the file system it looks at).

How it works: ROS 2 here is the PyPI wheels of a ROS release (`pip install 'sdrpeer[ros2]'`:
rclpy with Fast DDS, the message packages) in the same environment as sdrpeer; `available()`
finds `rclpy` without importing it (an import loads DDS: ~0.3 s and ~40 MB). The wheels keep their
shared libraries in `site-packages/ros_*.libs` and `PREFIX/lib`, which must be on
`LD_LIBRARY_PATH` before the interpreter starts (their `ros-wheels-bootstrapper` re-executes every
Python process once to set it); `process_env` sets it, marks the bootstrap done so nothing
re-executes, and points `AMENT_PREFIX_PATH` at the prefix (the message packages' index).

DDS discovery (`Ros2Net`): a fleet is one ROS 2 domain (`ROS_DOMAIN_ID`, 0..101: the agent's
`ros2_domain` setting; by default the agent's own ROS_DOMAIN_ID, else `default_domain("sdrpeer")`,
a fixed domain other than 0, so stock ROS 2 nodes on a robot do not join the fleet's graph).
Automatic discovery is kept on the robot's own machine (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`:
no multicast onto the lab's Wi-Fi) and the other robots are named as static peers
(`ROS_STATIC_PEERS`, their addresses from the membership), so a fleet's nodes on different robots
find each other and nothing else does.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import zlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

__all__ = ["DOMAIN_MAX", "Ros2Net", "available", "default_domain", "process_env"]

DOMAIN_MAX: Final = 101
"""The highest ROS_DOMAIN_ID every DDS implementation accepts on Linux (ROS 2's guidance)."""
BOOTSTRAP_DONE: Final = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"


def available() -> str | None:
    """None if rclpy can be imported here, else why not (said by the agent and `members`)."""
    try:
        found = importlib.util.find_spec("rclpy") is not None
    except (ImportError, ValueError):
        found = False
    if not found:
        return "ROS 2 is not installed here (pip install 'sdrpeer[ros2]')"
    return None


def default_domain(cluster: str) -> int:
    """The ROS 2 domain of a fleet named `cluster`: 1..DOMAIN_MAX, stable across releases
    (CRC-32 of the name; 0, every stock ROS 2 install's domain, is never chosen)."""
    return 1 + zlib.crc32(cluster.encode()) % DOMAIN_MAX


@dataclass(frozen=True, slots=True)
class Ros2Net:
    """How one robot's ROS 2 processes discover the fleet's other nodes."""

    domain: int
    peers: tuple[str, ...] = ()
    """The other robots' addresses (IPs or names)."""
    automatic: str = "LOCALHOST"
    """ROS_AUTOMATIC_DISCOVERY_RANGE: OFF, LOCALHOST, SUBNET or SYSTEM_DEFAULT."""

    def env(self) -> dict[str, str]:
        """The ROS_* variables for a ROS 2 process of this robot."""
        out = {
            "ROS_DOMAIN_ID": str(self.domain),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": self.automatic,
        }
        peers = sorted(p for p in set(self.peers) if p and not _loopback(p))
        if peers:
            out["ROS_STATIC_PEERS"] = ";".join(peers)
        return out


def _loopback(address: str) -> bool:
    return address.startswith("127.") or address in ("localhost", "::1")


def _library_dirs(prefix: Path) -> list[str]:
    site = prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}"
    dirs = [str(prefix / "lib")]
    packages = site / "site-packages"
    if packages.is_dir():
        dirs += sorted(str(p.resolve()) for p in packages.glob("ros_*.libs") if p.is_dir())
    return dirs


def process_env(
    base: Mapping[str, str], net: Ros2Net | None = None, *, prefix: str | None = None
) -> dict[str, str]:
    """`base` plus what a ROS 2 process of this environment needs (see the module's doc): the
    library path (ours first, `base`'s after, no repeats), the bootstrap marked done, the ament
    index, and `net`'s discovery settings when given."""
    root = Path(prefix or sys.prefix)
    env = dict(base)
    parts: list[str] = []
    for part in (*_library_dirs(root), *env.get("LD_LIBRARY_PATH", "").split(os.pathsep)):
        if part and part not in parts:
            parts.append(part)
    env["LD_LIBRARY_PATH"] = os.pathsep.join(parts)
    env[BOOTSTRAP_DONE] = "1"
    ament = [str(root), *(p for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p)]
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(dict.fromkeys(ament))
    if net is not None:
        env.update(net.env())
    return env


def static_peers(addresses: Iterable[str]) -> tuple[str, ...]:
    """Robot addresses (`host:port` or plain hosts) as ROS_STATIC_PEERS entries (hosts only)."""
    out: list[str] = []
    for a in addresses:
        host = a.rsplit(":", 1)[0] if a.count(":") == 1 else a
        host = host.strip("[]")
        if host and host not in out:
            out.append(host)
    return tuple(out)
