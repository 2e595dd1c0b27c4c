"""Fixtures shared by more than one test module, and the check that tests leave no agent behind.

Every process a test session starts carries `SDRPEER_TEST_SESSION` (set here, one value per
pytest process: each xdist worker has its own), whatever started it: a `RealCluster`, a lab
started in-process or by a `sdrpeer lab up` subprocess, their component hosts. When the last test
of a module has been torn down (its module's fixtures with it), whatever still carries this
process's value is waited for (bounded) and then SIGKILLed with its group; an `sdrpeer agent`
among them fails that test's teardown, naming it: an agent that outlived its test is a bug (issue
30: one ran on for 33 minutes after a passing test).
"""

from __future__ import annotations

import os
import secrets
import signal
import time
from collections.abc import Generator, Iterator
from pathlib import Path

import psutil
import pytest

from sdrpeer.lab.procs import is_agent_command
from tests.hostctl import HostPool
from tests.realnet import RealCluster

SESSION_ENV = "SDRPEER_TEST_SESSION"
LEFT_WAIT = 5.0
"""How long processes found at a module's end may take to exit on their own (s)."""


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[RealCluster]:
    """Real agent processes on loopback, all killed at teardown."""
    net = RealCluster(tmp_path / "net")
    try:
        yield net
    finally:
        net.close()


@pytest.fixture
def hosts(tmp_path: Path) -> Iterator[HostPool]:
    """Component hosts run by hand over their control channel, all closed at teardown."""
    pool = HostPool(tmp_path)
    yield pool
    pool.close_all()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The tests that take 30 s or more by design (`slow`) go first: run side by side
    (`tools/check` runs pytest-xdist workers), a long test started last would end the run alone."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def pytest_configure(config: pytest.Config) -> None:
    """Mark this pytest process's children (an xdist worker marks its own), and give this
    process's ROS 2 participants (the probe, the hosts and agents it starts) a DDS domain of their
    own, discovery kept on the machine: the two workers of one run, and two runs side by side,
    do not hear each other's topics."""
    os.environ[SESSION_ENV] = f"{os.getpid()}-{secrets.token_hex(8)}"
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw")
    run = os.getppid() if "PYTEST_XDIST_WORKER" in os.environ else os.getpid()
    index = int(worker) if worker.isdigit() else 0
    os.environ["ROS_DOMAIN_ID"] = str(20 + (run % 20) * 4 + index % 4)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"


def left_behind(mark: str) -> list[psutil.Process]:
    """Live processes (this one excepted) started with SDRPEER_TEST_SESSION=`mark`."""
    found = []
    for proc in psutil.process_iter():
        if proc.pid == os.getpid():
            continue
        try:
            if proc.status() != psutil.STATUS_ZOMBIE and proc.environ().get(SESSION_ENV) == mark:
                found.append(proc)
        except psutil.Error:
            continue
    return found


def _describe(proc: psutil.Process) -> str:
    try:
        return f"pid {proc.pid}: {' '.join(proc.cmdline())[:300]}"
    except psutil.Error:
        return f"pid {proc.pid}: (gone)"


def _is_agent(proc: psutil.Process) -> bool:
    try:
        cmdline = proc.cmdline()
    except psutil.Error:
        return False
    return is_agent_command(cmdline)


def reap_left_behind(mark: str, wait: float = LEFT_WAIT) -> list[str]:
    """Wait up to `wait` s for the marked processes to exit, SIGKILL the rest (and their
    groups); the agents among them, described."""
    procs = left_behind(mark)
    if not procs:
        return []
    _, alive = psutil.wait_procs(procs, timeout=wait)
    agents = [_describe(p) for p in alive if _is_agent(p)]
    for proc in alive:
        try:
            if os.getpgid(proc.pid) == proc.pid:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.kill()
        except (psutil.Error, ProcessLookupError, PermissionError):
            continue
    psutil.wait_procs(alive, timeout=2.0)
    return agents


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None]:
    """After a module's last test (and its module fixtures) is torn down: nothing it started
    may still run; a left agent fails this teardown."""
    result = yield
    module = getattr(item, "module", None)
    if nextitem is not None and getattr(nextitem, "module", None) is module:
        return result
    started = time.monotonic()
    agents = reap_left_behind(os.environ[SESSION_ENV])
    if agents:
        where = module.__name__ if module is not None else item.nodeid
        raise AssertionError(
            f"{where} left {len(agents)} agent process(es) running (killed now, "
            f"{time.monotonic() - started:.1f} s after its last test):\n  " + "\n  ".join(agents)
        )
    return result
