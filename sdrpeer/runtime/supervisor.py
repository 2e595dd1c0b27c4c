"""One supervisor per instance: start its host, watch it, restart it, stop it, measure it.

How it works: `start()` creates one life task. It spawns the host (argv from the launcher, the
child's end of a socket pair passed as SDRPEER_CONTROL_FD, output appended to the instance log)
and then *awaits the process*, so an exit is noticed the moment the kernel reports it. An exit
nobody asked for goes to the `RestartPolicy`: wait the backoff delay (state BACKOFF) and spawn
again, or give up (state FAILED). `stop()` is graceful: the `exit` command, then SIGTERM after
`exit_timeout`, then SIGKILL after `term_timeout`. A host that sends no hello within
`hello_timeout`, or breaks the control protocol, is killed and counts as a failure; so is one
silent for `heartbeat_timeout` (or its instance's `watchdog_s`) once initialized, outside a
command (the watchdog: a hung host is a crash to Table III, and its `last_error` says "hung"; a
command such as `activate` running a long on_activated has its own timeout instead).
States: STOPPED, STARTING (spawned, no INACTIVE yet), the host's own lifecycle states (CREATED,
INACTIVE, ACTIVE, ERROR, FINALIZED), STOPPING, BACKOFF, FAILED; every change is timestamped.
Trouble is passed on at once (sdrpeer.runtime.problems): each `fault` report is kept (the last
`max_faults`) and goes to `on_fault(sup, kind, detail)`; an ERROR no fault caused and an exit
nobody asked for go to `on_problem(sup, cause)`. A `refused` report (a receiver refuses one of
the host's outgoing connections; rate-limited by the host) is kept per connection in `refusals`
until the host says it got through, and goes to `on_refused(sup, report)` at once.
`snapshot()`/`restore(state)` move a component's working state (sdrpeer.runtime.handoff), at
most `max_state` bytes.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import subprocess
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import psutil

from sdrpeer.control import messages
from sdrpeer.control.agent_side import ControlChannel
from sdrpeer.control.messages import (
    Activate,
    Command,
    Deactivate,
    Exit,
    Heartbeat,
    Hello,
    Reply,
    Report,
    Reset,
    Restore,
    State,
)
from sdrpeer.errors import CommandError, ConfigError
from sdrpeer.runtime import problems
from sdrpeer.runtime.backoff import RestartPolicy
from sdrpeer.runtime.config import SupervisorConfig
from sdrpeer.runtime.handoff import give_state, take_snapshot
from sdrpeer.runtime.launch import (
    create_process,
    exit_text,
    host_argv,
    host_env,
    log_path,
    open_log,
    preexec,
    private_dir,
    remove_dir,
    wait_exit,
)
from sdrpeer.runtime.rates import port_rates
from sdrpeer.runtime.spec import ConnectionSpec, InstanceSpec
from sdrpeer.vocabulary import InstanceState, LifecycleState, ProcessState

log = logging.getLogger(__name__)
LIFECYCLE = tuple(c.T for c in (Activate, Deactivate, Reset, Exit, Restore))
"""Commands whose callbacks may hold the host's loop for a while (the watchdog waits for them,
up to the command timeout)."""


class Supervisor:
    """Runs and watches the host of one instance."""

    def __init__(
        self,
        spec: InstanceSpec,
        data_dir: Path,
        config: SupervisorConfig,
        on_change: Callable[[Supervisor], None] = lambda s: None,
        *,
        on_fault: Callable[[Supervisor, str, str], None] = lambda s, k, d: None,
        on_problem: Callable[[Supervisor, str], None] = lambda s, c: None,
        on_refused: Callable[[Supervisor, messages.Refused], None] = lambda s, r: None,
        data_keys: Callable[[], Sequence[bytes]] = tuple,
        launch_env: Callable[[InstanceSpec], Mapping[str, str]] = lambda s: {},
    ) -> None:
        self.spec = spec
        self.data_dir = data_dir
        self.config = config
        self.on_change = on_change
        self.on_fault = on_fault
        """Called at once with (self, kind, detail) for every fault the component reports."""
        self.on_problem = on_problem
        """Called at once with (self, cause): component_error or crashed (runtime.problems)."""
        self.on_refused = on_refused
        """Called at once with (self, report) for every `refused` report of the host."""
        self.refusals: dict[str, dict[str, Any]] = {}
        """Connection id -> why its receiver refuses it now: `{"error", "ts", "count"}` (the
        last reason, when it was reported, refusals in all); gone once it got through."""
        self.data_keys = data_keys  # what a new host authenticates its data connections with
        self.launch_env = launch_env  # what the agent adds to a new host's environment
        self.faults: deque[problems.Fault] = deque(maxlen=config.max_faults)
        """The last faults reported, oldest first."""
        self.policy = RestartPolicy(config.restart)
        self.state: InstanceState = ProcessState.STOPPED
        self.since = time.time()
        self.history: deque[tuple[float, InstanceState]] = deque(maxlen=32)
        self.pid: int | None = None
        self.restarts = 0
        self.last_error: str | None = None
        self.exit_noticed: float | None = None
        self.last_exit: int | None = None
        self.hello: Hello | None = None
        """The running host's hello (None until it said it)."""
        self.ports: dict[str, dict[str, int]] = {}
        self.endpoints: dict[str, list[str]] = {}
        """A hosted ROS 2 node's topics and services: name -> [direction, ROS type]."""
        self.port_rates: dict[str, dict[str, float]] = {}
        """Port -> frames and bytes per second, in and out, between the last two heartbeats."""
        self.data_plane: dict[str, int] = {}
        """The host's data server counters from its last heartbeat (accepted, rejected,
        refused_auth, deliver_error, shm, acked)."""
        self.out_bps = 0.0
        self.out_lost_ps = 0.0
        """Frames per second its outgoing connections lost to full buffers (see `sample`)."""
        """Bytes per second sent by the OutPorts between the last two `sample` calls."""
        self._last_sent: tuple[float, int, int] | None = None
        self.connections: dict[str, tuple[ConnectionSpec, str]] = {}
        self.start_latency: float | None = None
        self.cpu_pct = 0.0
        self.rss = 0
        self.protocol_errors = 0
        self._proc: asyncio.subprocess.Process | None = None
        self._channel: ControlChannel | None = None
        self._ps: psutil.Process | None = None
        self._life: asyncio.Task[None] | None = None
        self._stopping = False
        self._spawned = 0.0
        self._run_dir: Path | None = None
        self._watchdog: asyncio.TimerHandle | None = None
        self._heard = 0.0  # loop time of the host's last message
        self._beat_at = 0.0  # loop time of its last heartbeat
        self._suspect_since: float | None = None  # the watchdog found it silent (to confirm)
        self._kill_reason: str | None = None

    @property
    def name(self) -> str:
        """The instance name."""
        return self.spec.name

    @property
    def alive(self) -> bool:
        """Whether a host process is running right now."""
        return self._proc is not None and self._proc.returncode is None

    def _remove_run_dir(self) -> None:
        if self._run_dir is not None:
            remove_dir(self._run_dir)
            self._run_dir = None

    @property
    def running(self) -> bool:
        """Whether a life (spawn, run, backoff) is under way: stop() must come before forgetting."""
        return self._life is not None and not self._life.done()

    def stop_requested(self) -> bool:
        """Whether stop() was called since the last start()."""
        return self._stopping

    def log_file(self) -> Path:
        """The instance log."""
        return log_path(self.data_dir, self.name)

    def _set(self, state: InstanceState) -> None:
        if state != self.state:
            self.state = state
            self.since = time.time()
            self.history.append((self.since, state))
            self.on_change(self)

    # ----------------------------------------------------------------- life
    def start(self) -> None:
        """Start the host (no-op while one runs or is scheduled); a FAILED instance tries again."""
        if self._life is not None and not self._life.done():
            return
        self._stopping = False
        if self.state == ProcessState.FAILED:
            self.policy.reset()
        self._life = asyncio.create_task(self._run(), name=f"supervisor-{self.name}")
        # at once, not when the process exists: until then the instance manager must not take a
        # supervisor still STOPPED from an earlier life for a finished one and forget it (its
        # process would run on, untracked)
        self._set(ProcessState.STARTING)

    async def stop(self) -> None:
        """Stop gracefully (exit, then SIGTERM, then SIGKILL) and do not restart."""
        self._stopping = True
        life = self._life
        if life is None or life.done():
            self._remove_run_dir()
            return
        if self.alive:
            await self._terminate()
        else:
            life.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await life
        self._remove_run_dir()

    def kill_now(self) -> None:
        """SIGKILL the host at once, without a word to it (an agent out of time to stop)."""
        self._stopping = True
        proc = self._proc
        if proc is not None and proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()

    async def restart(self) -> None:
        """Stop, forget past failures, start again."""
        await self.stop()
        self.policy.reset()
        self.start()

    def _live(self, t: str) -> ControlChannel:
        """The channel to the running host; CommandError "closed" (saying `t`) if none is."""
        if self._channel is None or self._channel.closed:
            raise CommandError(t, "closed", f"{self.name} is {self.state}")
        return self._channel

    async def command(self, cmd: Command) -> Reply:
        """Send a command to the host; CommandError if it is not running or refuses."""
        return await self._live(cmd.T).command(cmd)

    async def snapshot(self) -> Any:
        """The component's state (its on_snapshot); CommandError if refused or over max_state."""
        return await take_snapshot(self._live("snapshot"), self.config.max_state)

    async def restore(self, state: Any) -> None:
        """Hand `state` to the component's on_restore; StateError if too big, CommandError."""
        await give_state(self._live("restore"), state, self.config.max_state)

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            while not self._stopping:
                started = loop.time()
                rc: int | None = None
                try:
                    proc = await self._spawn()
                except OSError as e:
                    self.last_error = f"cannot start: {e}"
                    log.warning("%s: %s", self.name, self.last_error)
                else:
                    rc = await proc.wait()
                    self.exit_noticed = loop.time()
                    await self._after_exit(rc)
                if self.stop_requested():
                    break
                if rc is not None:
                    why = self._kill_reason
                    self.last_error = f"{why}; {exit_text(rc)}" if why else exit_text(rc)
                    self._problem(problems.CRASHED)  # an exit nobody asked for
                delay = self.policy.on_exit(started, loop.time())
                if delay is None:
                    log.error(
                        "%s: giving up after %d fast failures", self.name, self.policy.failures
                    )
                    self._set(ProcessState.FAILED)
                    return
                log.warning("%s: %s; restarting in %.2fs", self.name, self.last_error, delay)
                self._set(ProcessState.BACKOFF)
                await asyncio.sleep(delay)
                self.restarts += 1
        finally:
            if self.state != ProcessState.FAILED:
                self._set(ProcessState.STOPPED)

    async def _spawn(self) -> asyncio.subprocess.Process:
        try:
            argv = host_argv(self.spec)
        except ConfigError as e:
            raise OSError(str(e)) from None
        if self._run_dir is None:
            self._run_dir = private_dir(self.name)
        parent, child = socket.socketpair()
        env = host_env(
            {**os.environ, **self.launch_env(self.spec)},
            self.spec,
            fd=child.fileno(),
            data_host=self.config.data_host,
            run_dir=self._run_dir,
            data_keys=self.data_keys(),
        )
        out = open_log(self.data_dir, self.name, argv)
        self._spawned = asyncio.get_running_loop().time()
        try:
            proc = await create_process(
                argv,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=out,
                pass_fds=(child.fileno(),),
                env=env,
                preexec_fn=preexec(self.config.host_nice),
                start_new_session=False,
            )
        except asyncio.CancelledError:
            parent.close()  # stopped while the host was being made: create_process killed it
            raise
        except OSError:
            parent.close()
            raise
        finally:
            out.close()
            child.close()
        self._proc, self.pid, self._kill_reason = proc, proc.pid, None
        self.hello, self.ports, self.connections, self.start_latency = None, {}, {}, None
        self.port_rates = {}
        self.data_plane = {}
        self.refusals = {}
        try:
            self._ps = psutil.Process(proc.pid)
            self._ps.cpu_percent(None)
        except psutil.Error:
            self._ps = None
        self._set(ProcessState.STARTING)
        self._channel = ControlChannel(
            parent,
            self._on_report,
            self._on_channel_closed,
            name=self.name,
            command_timeout=self.config.command_timeout,
        )
        await self._channel.open()
        loop = asyncio.get_running_loop()
        self._watchdog = loop.call_later(self.config.hello_timeout, self._hello_overdue, proc)
        self._heard = loop.time()
        log.info("%s: started pid %d: %s", self.name, proc.pid, " ".join(argv))
        return proc

    async def _after_exit(self, rc: int) -> None:
        self.last_exit = rc
        if self._watchdog is not None:
            self._watchdog.cancel()
        if self._channel is not None:
            self.protocol_errors += self._channel.counters["protocol_errors"]
            await self._channel.close()
        self._channel, self._ps, self.pid = None, None, None
        self.connections, self.ports, self.hello = {}, {}, None
        self.port_rates = {}
        self.data_plane = {}
        self.refusals = {}
        self.cpu_pct, self.rss = 0.0, 0
        log.info("%s: host %s", self.name, exit_text(rc))

    async def _terminate(self) -> None:
        proc = self._proc
        assert proc is not None
        self._set(ProcessState.STOPPING)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.config.exit_timeout
        if self._channel is not None and not self._channel.closed:
            with contextlib.suppress(CommandError):
                timeout = self.config.exit_timeout
                await self._channel.command(Exit(timeout), wait=timeout)
        if await wait_exit(proc, deadline - loop.time()):
            return
        log.warning("%s: no exit after %.1fs; SIGTERM", self.name, self.config.exit_timeout)
        with contextlib.suppress(ProcessLookupError):
            proc.terminate()
        if await wait_exit(proc, self.config.term_timeout):
            return
        log.warning("%s: still alive after SIGTERM; SIGKILL", self.name)
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
        await proc.wait()

    def _kill(self, proc: asyncio.subprocess.Process, why: str) -> None:
        if proc is self._proc and proc.returncode is None and not self._stopping:
            self._kill_reason = why
            log.warning("%s: %s; killing the host", self.name, why)
            with contextlib.suppress(ProcessLookupError):
                proc.kill()

    def _hello_overdue(self, proc: asyncio.subprocess.Process) -> None:
        if proc is self._proc and self.hello is None:
            self._kill(proc, f"no hello within {self.config.hello_timeout}s")

    def _on_channel_closed(self, reason: str | None) -> None:
        proc = self._proc
        if proc is None:
            return
        if reason is not None:  # a protocol error: the host is failed
            self._kill(proc, reason)
        else:  # EOF: the host is most likely exiting; kill it if it lingers
            asyncio.get_running_loop().call_later(
                self.config.eof_grace, self._kill, proc, "control channel closed by the host"
            )

    # ----------------------------------------------------------------- reports
    def _on_report(self, report: Report) -> None:
        match report:
            case Hello():
                self._on_hello(report)
            case State():
                self._on_state(report)
            case Heartbeat():
                self._on_heartbeat(report)
            case messages.Fault():
                self._on_fault(report)
            case messages.Refused():
                self._on_refused(report)
            case _:  # a reply is the channel's
                pass

    def _on_hello(self, msg: Hello) -> None:
        self.hello = msg
        self._heard = asyncio.get_running_loop().time()
        self.on_change(self)

    def silence_limit(self) -> float:
        """Seconds the host may stay silent now before the watchdog kills it (0: never): the
        hello timeout until it is initialized, then its heartbeat deadline."""
        if self.start_latency is None:
            return self.config.hello_timeout
        w = self.spec.watchdog_s
        return self.config.heartbeat_timeout if w is None else w

    def _arm_watchdog(self, proc: asyncio.subprocess.Process) -> None:
        """(Re)schedule the check for the moment the host's silence would run out."""
        if self._watchdog is not None:
            self._watchdog.cancel()
            self._watchdog = None
        limit = self.silence_limit()
        if limit > 0 and proc is self._proc and proc.returncode is None:
            loop = asyncio.get_running_loop()
            self._watchdog = loop.call_at(self._heard + limit, self._silence_check, proc)

    def _silence_check(self, proc: asyncio.subprocess.Process) -> None:
        self._watchdog = None
        limit = self.silence_limit()
        if limit <= 0 or proc is not self._proc or self.state == ProcessState.STOPPING:
            return
        now = asyncio.get_running_loop().time()
        since = None if self._channel is None else self._channel.pending_since(LIFECYCLE)
        if since is not None and now - since < self.config.command_timeout:
            # inside a lifecycle call (on_activated touching its memory reserve...): the
            # command's own timeout applies; the silence counts again from its end
            self._heard = now
        silent = now - self._heard
        if silent < limit:
            self._arm_watchdog(proc)
        elif self._suspect_since is not None and self._heard < self._suspect_since:
            self._kill(proc, f"hung: no heartbeat for {silent:.1f}s (watchdog {limit:g}s)")
        else:
            # Look once more before killing: when this agent's own loop was stalled, the host's
            # heartbeats wait unread in the socket, and the task that reads them runs only in
            # the loop's next turn, after this timer. A host that still says nothing then is hung.
            self._suspect_since = now
            loop = asyncio.get_running_loop()
            self._watchdog = loop.call_later(
                self.config.watchdog_confirm, self._silence_check, proc
            )

    def _on_state(self, msg: State) -> None:
        state = LifecycleState(msg.state)  # the control codec checked it is one
        self._heard = asyncio.get_running_loop().time()
        if state is LifecycleState.INACTIVE and self.start_latency is None:
            self.start_latency = self._heard - self._spawned
            if self._proc is not None:  # initialized: from now on the heartbeat deadline
                self._arm_watchdog(self._proc)
        if msg.error:
            self.last_error = msg.error
        problem = problems.problem_of_state(self.state, msg, self._stopping)
        if self.state != ProcessState.STOPPING:
            self._set(state)
        self._problem(problem)

    def _on_heartbeat(self, msg: Heartbeat) -> None:
        now = asyncio.get_running_loop().time()
        if self.ports:
            self.port_rates = port_rates(self.ports, msg.ports, now - self._beat_at)
        self._heard = self._beat_at = now
        self.ports = msg.ports
        self.data_plane = msg.data or {}
        self.endpoints = msg.endpoints or {}

    def _on_fault(self, msg: messages.Fault) -> None:
        fault = problems.fault_from_report(msg, time.time())
        self.faults.append(fault)
        self.last_error = f"fault {fault.kind}: {fault.detail}"
        log.warning("%s: %s", self.name, self.last_error)
        problems.call_hook("on_fault", self.on_fault, self, fault.kind, fault.detail)
        self.on_change(self)

    def _on_refused(self, msg: messages.Refused) -> None:
        if msg.error is None:
            self.refusals.pop(msg.conn, None)
            log.info("%s: connection %s is accepted again", self.name, msg.conn)
        else:
            before = self.refusals.get(msg.conn, {}).get("count", 0)
            self.refusals[msg.conn] = {
                "error": msg.error,
                "ts": msg.ts,
                "count": before + msg.count,
            }
            log.warning(
                "%s: connection %s (%s -> %s %s) refused: %s",
                self.name,
                msg.conn,
                msg.from_,
                msg.to,
                msg.in_port,
                msg.error,
            )
        problems.call_hook("on_refused", self.on_refused, self, msg)
        self.on_change(self)  # the gossip record counts the connections refused now

    def _problem(self, cause: str | None) -> None:
        if cause is not None:
            log.warning("%s: %s (%s)", self.name, cause, self.last_error)
            problems.call_hook("on_problem", self.on_problem, self, cause)

    # ----------------------------------------------------------------- metrics
    def sample(self) -> tuple[float, int]:
        """Measure the host's CPU % (since the last call) and RSS bytes now, and per second
        since the last call the bytes its OutPorts sent (`out_bps`) and the frames their
        connections lost to full buffers (`out_lost_ps`), from the heartbeat's counters."""
        now = time.monotonic()
        sent = sum(c.get("bytes_out", 0) for c in self.ports.values())
        lost = sum(c.get("overflowed", 0) for c in self.ports.values())
        last = self._last_sent
        if last is not None and sent >= last[1] and lost >= last[2] and now > last[0]:
            self.out_bps = (sent - last[1]) / (now - last[0])
            self.out_lost_ps = (lost - last[2]) / (now - last[0])
        else:  # the first sample, or a new host process whose counters began again
            self.out_bps = self.out_lost_ps = 0.0
        self._last_sent = (now, sent, lost)
        ps = self._ps
        if ps is None:
            self.cpu_pct, self.rss = 0.0, 0
        else:
            try:
                with ps.oneshot():
                    self.cpu_pct, self.rss = ps.cpu_percent(None), ps.memory_info().rss
            except psutil.Error:
                self.cpu_pct, self.rss = 0.0, 0
        return self.cpu_pct, self.rss

    def tcp_address(self) -> str | None:
        """Where senders on other robots reach this host (its TCP data address), if running."""
        tcp = None if self.hello is None else self.hello.data.get("tcp")
        return f"tcp://{tcp}" if tcp else None

    def data_address(self) -> str | None:
        """Where senders on this robot reach this host: its Unix socket, else its TCP address."""
        data = {} if self.hello is None else self.hello.data
        if data.get("unix"):
            return f"unix://{data['unix']}"
        if data.get("tcp"):
            return f"tcp://{data['tcp']}"
        return None
