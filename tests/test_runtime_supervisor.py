"""Supervisor against the fake host: start, states, crash -> noticed at once -> backoff, stop."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import replace
from pathlib import Path

import psutil
import pytest

from sdrpeer.control.messages import Activate
from sdrpeer.errors import CommandError
from sdrpeer.launch.policy import LaunchPolicy
from sdrpeer.monitor.procstats import ProcessTreeMeter
from sdrpeer.runtime.backoff import RestartConfig
from sdrpeer.runtime.config import SupervisorConfig
from sdrpeer.runtime.config import fast_test as supervisor_fast
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.runtime.supervisor import Supervisor
from tests.wait import stays_async, until_async

FAKE_HOST = str(Path(__file__).with_name("fake_host.py"))


WITH_EXEC = LaunchPolicy(("python", "exec"))
"""The fake hosts are run by the exec launcher, off by default."""


def fake(name: str = "A", mode: str = "", heartbeat: float = 0.5) -> InstanceSpec:
    argv = [sys.executable, FAKE_HOST, f"--mode={mode}", f"--heartbeat={heartbeat}"]
    return InstanceSpec.from_json({"name": name, "launcher": "exec", "target": argv})


@pytest.fixture
async def sups(tmp_path: Path) -> AsyncIterator[Callable[..., Supervisor]]:
    made: list[Supervisor] = []

    def make(spec: InstanceSpec, config: SupervisorConfig | None = None) -> Supervisor:
        sup = Supervisor(spec, tmp_path, config or supervisor_fast())
        made.append(sup)
        return sup

    yield make
    for sup in made:
        pid = sup.pid
        try:
            await asyncio.wait_for(sup.stop(), 5.0)
        finally:
            if pid is not None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)


async def test_start_states_commands_and_log(sups, tmp_path):
    sup = sups(fake())
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    assert sup.pid is not None
    assert sup.hello is not None
    assert sup.hello.pid == sup.pid
    assert sup.data_address() is not None
    assert sup.start_latency is not None
    assert 0 < sup.start_latency < 5
    await sup.command(Activate())
    await until_async("ACTIVE", lambda: sup.state, lambda s: s == "ACTIVE")
    assert [s for _, s in sup.history] == ["STARTING", "CREATED", "INACTIVE", "ACTIVE"]
    assert all(a <= b for (a, _), (b, _) in zip(sup.history, list(sup.history)[1:], strict=False))
    await until_async("a heartbeat", lambda: sup.ports)
    cpu, rss = sup.sample()
    assert rss > 1_000_000
    assert cpu > 0  # the meter was primed at the fork: the host's start-up since then counts
    assert (sup.cpu_pct, sup.rss) == (cpu, rss)
    log = (tmp_path / "instances" / "A.log").read_text()
    assert "sdrpeer: starting A:" in log
    assert "fake-host: got activate" in log
    await sup.stop()
    assert sup.state == "STOPPED"
    assert sup.last_exit == 0
    assert sup.pid is None
    assert sup.sample() == (0.0, 0)  # nothing to measure


async def test_sigkill_is_noticed_at_once_and_restarted_with_backoff(sups):
    sup = sups(fake())
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    old = sup.pid
    loop = asyncio.get_running_loop()
    killed = loop.time()
    os.kill(old, signal.SIGKILL)
    await until_async("the exit", lambda: sup.exit_noticed, lambda t: t is not None)
    assert sup.exit_noticed >= killed
    assert sup.last_error == "killed by SIGKILL"  # seen as an exit, not by the watchdog (hung)
    await until_async(
        "the restart",
        lambda: (sup.state, sup.pid),
        lambda seen: seen[0] == "INACTIVE" and seen[1] != old,
    )
    assert sup.restarts == 1
    states = [s for _, s in sup.history]
    assert states[states.index("BACKOFF") + 1] == "STARTING"


async def test_fast_failures_give_up_then_restart_tries_again(sups):
    spec = InstanceSpec.from_json(
        {"name": "Bad", "launcher": "exec", "target": [sys.executable, "-c", "exit(3)"]}
    )
    config = replace(supervisor_fast(), restart=RestartConfig(0.01, 2, 0.05, 5, 3))
    sup = sups(spec, config)
    sup.start()
    await until_async("FAILED", lambda: sup.state, lambda s: s == "FAILED")
    assert sup.restarts == 2
    assert sup.last_error == "exited with code 3"
    await sup.restart()
    await until_async(
        "FAILED again", lambda: (sup.state, sup.restarts), lambda seen: seen == ("FAILED", 4)
    )


async def test_missing_executable_fails(sups):
    spec = InstanceSpec.from_json({"name": "X", "launcher": "exec", "target": ["/nonexistent/x"]})
    config = replace(supervisor_fast(), restart=RestartConfig(0.01, 2, 0.05, 5, 2))
    sup = sups(spec, config)
    sup.start()
    await until_async("FAILED", lambda: sup.state, lambda s: s == "FAILED")
    assert "cannot start" in (sup.last_error or "")


@pytest.mark.parametrize(
    ("mode", "code"), [("", 0), ("ignore_exit", -signal.SIGTERM), ("ignore_exit,ignore_term", -9)]
)
async def test_graceful_stop_escalates(sups, mode, code):
    # a host that obeys gets 10 s (a loaded machine is slow to exit); the others 1 s per step
    config = supervisor_fast()
    if code == 0:
        config = replace(config, exit_timeout=10.0, term_timeout=10.0)
    sup = sups(fake(mode=mode), config)
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    await sup.stop()
    took = loop.time() - t0
    assert sup.last_exit == code
    assert sup.state == "STOPPED"
    waited = {0: 0.0, -signal.SIGTERM: config.exit_timeout}.get(
        code, config.exit_timeout + config.term_timeout
    )  # the timeouts it had to wait out before the next step
    assert waited <= took < waited + 10.0
    await stays_async(  # a stop is not a failure: no restart
        "STOPPED, no restart",
        lambda: (sup.state, sup.restarts),
        lambda seen: seen == ("STOPPED", 0),
        window=0.2,
    )


async def test_protocol_error_kills_and_restarts(sups):
    sup = sups(fake(mode="garbage"))
    sup.start()
    await until_async("a restart", lambda: sup.restarts, lambda n: n >= 1)
    assert sup.protocol_errors >= 1
    assert "protocol error" in (sup.last_error or "")


async def test_no_hello_is_killed(sups):
    config = replace(supervisor_fast(), hello_timeout=0.3)
    sup = sups(fake(mode="no_hello"), config)
    sup.start()
    await until_async("a kill", lambda: sup.last_exit, lambda code: code is not None)
    assert sup.last_exit == -9
    assert "no hello within 0.3s" in (sup.last_error or "")


async def test_commands_fail_cleanly_when_not_running(sups):
    sup = sups(fake())
    with pytest.raises(CommandError, match="closed"):
        await sup.command(Activate())


async def test_the_agents_process_tree_meter_counts_hosts(sups):
    sup = sups(fake())
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    _, host_rss = sup.sample()
    _, tree_rss = ProcessTreeMeter(os.getpid(), include_root=False).measure()
    assert tree_rss >= host_rss > 0


@pytest.mark.parametrize("nice", [0, 5])
async def test_a_host_runs_host_nice_steps_nicer_than_its_agent(sups, nice):
    # A robot's components must not starve its agent (issue 30: ten agents' probes missed while
    # their hosts started on two cores); `host_nice` 0 keeps the agent's priority.
    sup = sups(fake(), supervisor_fast().with_(host_nice=nice))
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    assert sup.pid is not None
    assert psutil.Process(sup.pid).nice() == min(19, os.nice(0) + nice)


async def test_a_stop_while_the_host_is_being_made_leaves_no_orphan(
    sups, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Under load the process exists before create_subprocess_exec returns: a stop in that
    window must not leave it running (the chaos soak found such orphans piling up)."""
    real = asyncio.create_subprocess_exec
    forked: list[int] = []

    async def slow(*args: object, **kw: object) -> asyncio.subprocess.Process:
        proc = await real(*args, **kw)  # type: ignore[arg-type]
        forked.append(proc.pid)
        await asyncio.sleep(1.0)  # the rest of the set-up, slow on a loaded robot
        return proc

    monkeypatch.setattr(asyncio, "create_subprocess_exec", slow)
    sup = sups(fake())
    sup.start()
    await until_async("the fork", lambda: forked)
    await asyncio.wait_for(sup.stop(), 5.0)
    assert sup.state == "STOPPED"
    with pytest.raises(ProcessLookupError):  # reaped: not even a zombie left
        os.kill(forked[0], 0)


async def test_an_instance_dropped_while_its_host_starts_is_stopped_not_forgotten(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The instance manager forgets a supervisor only when its life is over: one that was
    started but whose process did not exist yet used to look STOPPED, was forgotten, and its
    host ran on untracked (the 10-robot chaos soak found hundreds)."""
    from sdrpeer.runtime.manager import InstanceManager  # noqa: PLC0415

    real = asyncio.create_subprocess_exec
    entered: list[bool] = []
    forked: list[int] = []

    async def slow(*args: object, **kw: object) -> asyncio.subprocess.Process:
        entered.append(True)
        await asyncio.sleep(0.5)  # a loaded robot: the fork comes late
        proc = await real(*args, **kw)  # type: ignore[arg-type]
        forked.append(proc.pid)
        return proc

    monkeypatch.setattr(asyncio, "create_subprocess_exec", slow)
    manager = InstanceManager(tmp_path, supervisor_fast(), interval=0.02, policy=WITH_EXEC)
    await manager.start()
    try:
        manager.set_desired([fake("A")])
        await until_async("the start under way", lambda: entered)
        assert manager.status_of("A")["state"] == "STARTING"  # not STOPPED from before
        manager.remove("A")  # dropped before its host exists
        await until_async("the fork", lambda: forked)
        await until_async("the host gone and forgotten", manager.status, lambda rows: rows == [])

        def gone() -> bool:
            try:
                os.kill(forked[0], 0)
            except ProcessLookupError:
                return True
            return False

        await until_async("the host process reaped", gone)
    finally:
        await manager.stop()


async def watched(sups, seen: list[str]):
    """A fake host beating every 0.1 s under a 0.6 s watchdog, initialized and heard from once;
    its problems' causes go to `seen`."""
    sup = sups(fake(heartbeat=0.1), replace(supervisor_fast(), heartbeat_timeout=0.6))
    sup.on_problem = lambda s, cause: seen.append(cause)
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    await until_async("a heartbeat", lambda: sup.ports)
    return sup


async def test_a_stopped_host_is_killed_by_the_watchdog_as_hung_and_restarted(sups):
    """SIGSTOP: the host goes silent; after its heartbeat deadline it is killed, counted as a
    crash (its last error says hung), and restarted."""
    seen: list[str] = []
    sup = await watched(sups, seen)
    old = sup.pid
    loop = asyncio.get_running_loop()
    stopped = loop.time()
    os.kill(old, signal.SIGSTOP)
    await until_async(
        "the watchdog's kill", lambda: sup.exit_noticed, lambda t: t is not None, within=5.0
    )
    took = sup.exit_noticed - stopped
    assert took >= 0.6 - 0.5  # silent since its last heartbeat, at most 0.5 s before the stop
    assert sup.last_error.startswith("hung: no heartbeat for "), sup.last_error
    assert "killed by SIGKILL" in sup.last_error
    assert seen == ["crashed"]
    await until_async(
        "the restart",
        lambda: (sup.state, sup.pid),
        lambda seen: seen[0] == "INACTIVE" and seen[1] != old,
    )


async def test_a_stall_of_the_agents_own_loop_does_not_make_its_hosts_hung(sups):
    """The agent's loop blocked past the deadline (a loaded robot): the host's heartbeats wait
    unread, and the watchdog timer runs before the task that reads them. It looks again before it
    kills: the host lives (before, it was killed as hung: 197 times in a 10-robot soak)."""
    seen: list[str] = []
    sup = await watched(sups, seen)
    pid = sup.pid
    for _ in range(3):
        time.sleep(1.2)  # noqa: ASYNC251 - the point: this loop does nothing for 1.2 s
        beats = sup.ports
        await until_async(
            "a heartbeat after the stall",
            lambda: sup.ports,
            lambda ports, before=beats: ports is not before,  # type: ignore[misc]
        )
    assert sup.exit_noticed is None
    assert sup.pid == pid
    assert seen == []


async def test_a_watchdog_of_zero_never_fires_and_an_instance_value_wins(sups):
    spec = replace(fake("Off"), watchdog_s=0.0)
    sup = sups(spec, replace(supervisor_fast(), heartbeat_timeout=0.5))
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    assert sup.silence_limit() == 0
    pid = sup.pid
    os.kill(pid, signal.SIGSTOP)
    try:
        await stays_async(  # three deadlines of the default: still not killed
            "not killed",
            lambda: (sup.pid, sup.exit_noticed),
            lambda seen: seen == (pid, None),
            window=1.5,
        )
    finally:
        os.kill(pid, signal.SIGCONT)
    long = sups(replace(fake("Long"), watchdog_s=30.0))
    long.start()
    await until_async("INACTIVE", lambda: long.state, lambda s: s == "INACTIVE")
    assert long.silence_limit() == 30.0


async def test_a_host_still_initializing_has_the_hello_timeout_not_the_heartbeat_deadline(sups):
    sup = sups(fake(heartbeat=0.1), replace(supervisor_fast(), heartbeat_timeout=0.5))
    assert sup.silence_limit() == sup.config.hello_timeout  # not yet initialized
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    assert sup.silence_limit() == 0.5


async def test_a_long_lifecycle_call_is_not_hung(sups):
    """The host is silent while it activates (on_activated touching a memory reserve): the
    watchdog waits for the command (its own timeout applies), then counts again."""
    sup = sups(
        fake(mode="slow_activate", heartbeat=0.1),
        replace(supervisor_fast(), heartbeat_timeout=0.5),
    )
    sup.start()
    await until_async("INACTIVE", lambda: sup.state, lambda s: s == "INACTIVE")
    pid = sup.pid
    await sup.command(Activate())  # 1.5 s without a heartbeat, three deadlines
    await until_async("ACTIVE", lambda: sup.state, lambda s: s == "ACTIVE")
    assert sup.pid == pid
    assert sup.exit_noticed is None
    os.kill(pid, signal.SIGSTOP)  # silent outside a command: the watchdog fires
    await until_async(
        "the watchdog's kill", lambda: sup.exit_noticed, lambda t: t is not None, within=5.0
    )
    assert sup.last_error.startswith("hung: ")
