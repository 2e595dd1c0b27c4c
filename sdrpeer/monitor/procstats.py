"""Real measurements of the processes a robot hosts: CPU % and resident memory, with psutil.

How it works: `ProcessTreeMeter` follows a root process (the agent) and all its descendants (the
component hosts), keeping one `psutil.Process` per pid so that `cpu_percent()` measures the time
between two calls. Processes that exit are dropped; new children are picked up on every call.
A measurement younger than `max_age` is answered again: finding the descendants reads every
process's /proc entry (psutil's `children`), and an agent samples on every instance change — ten
agents deploying twenty instances spent a sixth of their loops there, and CPU shares taken over a
few milliseconds swing between 0 and 100 % (a CPU trap raised and cleared within 3 ms).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import psutil


class ProcessTreeMeter:
    """CPU % (of one core) and RSS bytes of a process and its descendants."""

    def __init__(
        self,
        root_pid: int,
        *,
        include_root: bool = True,
        max_age: float = 0.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.root = psutil.Process(root_pid)
        self.include_root = include_root
        self.max_age = max_age
        """Seconds a measurement is answered again (0: measure on every call)."""
        self._clock = clock
        self._procs: dict[int, psutil.Process] = {}
        self._last: tuple[float, tuple[float, int]] | None = None

    def measure(self) -> tuple[float, int]:
        """(cpu %, rss bytes) summed over the tree (measured at most `max_age` ago)."""
        now = self._clock()
        last = self._last
        if last is not None and now - last[0] < self.max_age:
            return last[1]
        found = self._measure()
        self._last = (now, found)
        return found

    def _measure(self) -> tuple[float, int]:
        try:
            tree = self.root.children(recursive=True)
        except psutil.Error:
            tree = []
        if self.include_root:
            tree.append(self.root)
        cpu = 0.0
        rss = 0
        alive: dict[int, psutil.Process] = {}
        for proc in tree:
            known = self._procs.get(proc.pid, proc)
            try:
                with known.oneshot():
                    cpu += known.cpu_percent(None)
                    rss += known.memory_info().rss
            except psutil.Error:
                continue
            alive[proc.pid] = known
        self._procs = alive
        return cpu, rss


def trim_heap() -> None:
    """Collect garbage and hand freed heap pages back to the OS (glibc only; else a no-op).

    Start-up (imports, parsing files, binding) leaves freed but still resident heap behind; on a
    robot with 4 GB that matters less than on one with 512 MB, where every MiB is a component's.
    """
    import ctypes  # noqa: PLC0415  (only the agent needs it, once)
    import ctypes.util  # noqa: PLC0415
    import gc  # noqa: PLC0415

    gc.collect()
    name = ctypes.util.find_library("c")
    if name is None:
        return
    try:
        ctypes.CDLL(name).malloc_trim(0)
    except (OSError, AttributeError):
        return
