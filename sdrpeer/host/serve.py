"""The running host: data server, control channel (or standalone reporting), command loop, exit.

How it works: `Host.run` wraps the instance in its runner, starts the `DataServer` that resolves
in-port names to our runtime InPorts, then either opens the control channel (sends `hello`, then
initializes: the runner's state changes go out as `state` reports the moment they happen) or,
when standalone, activates at once and logs the port counters once a second. Commands are queued
by the channel and run one at a time, in order, by `_serve_commands`, each answered by exactly one
`reply` (`snapshot`'s state goes in `part` messages written with its reply, in one write).
Whatever ends the host (`exit`, SIGTERM/SIGINT, the control channel closing, the parent dying)
sets `stop` (`exit` at once, not behind a command still running, which is then abandoned and
answered `ok: false`); then the outgoing connections stop making senders wait (a component
blocked in `send()` on a receiver that refuses it, or is slow, lets go at once: finalizing
waits for its lock), the runner finalizes (deactivating first if active) within the timeout,
connections and the data server close, `exit` is answered, and the channel is closed after the
last report is written.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import re
import signal
import time
from typing import Any

from sdrpeer.control.host_side import ControlChannel, Refusal, Request
from sdrpeer.control.messages import Exit, Hello, Reply, Report
from sdrpeer.control.parts import parts
from sdrpeer.dataplane import DataServer
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.host.config import FINALIZE_TIMEOUT, STANDALONE_REPORT_INTERVAL, HostConfig
from sdrpeer.host.instance import HostedInstance, ReportTo, maybe_await
from sdrpeer.sdk import Component, ComponentRunner
from sdrpeer.vocabulary import LifecycleState

log = logging.getLogger("sdrpeer.host")


class Host:
    """One host process's asyncio side."""

    def __init__(self, config: HostConfig, component: Component) -> None:
        self.config = config
        self.component = component
        self.name = component.instance_name
        self.tmp_dir: str | None = None
        self.channel: ControlChannel | None = None
        self.stop = asyncio.Event()
        self.exit_request: tuple[int, Exit] | None = None
        """The `exit` command that ends us (its id and itself), if one does."""
        self._queue: asyncio.Queue[Request | Refusal] = asyncio.Queue()
        self._server: DataServer | None = None
        self._running: Request | None = None
        """The command being carried out, if one is."""
        self._error = "finalize failed"

    async def run(self) -> int:
        """Start, serve until told to stop, finalize; returns the exit code."""
        install_signals(asyncio.get_running_loop(), self.stop)
        component = self.component
        runner = ComponentRunner(component)
        if self.config.control_fd is not None:
            self.channel = await ControlChannel.open(
                self.config.control_fd,
                self._on_command,
                self._on_closed,
                self._counters,
                data_counters=self._data_counters,
                endpoints=getattr(component, "endpoints", None),
            )
            report: ReportTo = self.channel.send
        else:
            report = _no_report  # standalone: state changes are logged by the instance
        auth = DataAuth(self.config.data_keys)
        self.inst = HostedInstance(self.name, component, runner, report, clock=now, auth=auth)
        server = DataServer(
            self.inst.in_port,
            tcp_host=self.config.data_host,
            unix_path=self._unix_path(),
            auth=auth,
            resolve_service=self.inst.service,
        )
        self._server = server
        self.inst.on_taking = server.set_taking
        server.set_taking(self.inst.state == LifecycleState.ACTIVE)
        await maybe_await(server.start())
        data = dict(server.addresses)
        self.inst.own_addresses = frozenset(f"{kind}://{where}" for kind, where in data.items())
        if self.channel is not None:
            self.channel.send(
                Hello(
                    pid=os.getpid(),
                    component=type(component).__name__,
                    ports=self.inst.ports(),
                    params=self.inst.params(),
                    data=data,
                    services=self.inst.services() or None,
                )
            )
        else:
            log.info("standalone %s: ports %s, data %s", self.name, self.inst.ports(), data)
        self.inst.watch()
        tasks = [asyncio.create_task(self._start(standalone=self.channel is None))]
        if self.channel is not None:
            tasks.append(asyncio.create_task(self._serve_commands()))
        else:
            tasks.append(asyncio.create_task(self._log_counters()))
        await self.stop.wait()
        for task in tasks:
            task.cancel()
        self.inst.release_senders()
        code = await self._finalize(runner)
        await self.inst.close_connections()
        await maybe_await(server.close())
        await self._goodbye(code)
        return code

    async def _start(self, *, standalone: bool) -> None:
        """Initialize (and activate at once when standalone)."""
        try:
            await self.inst.runner.initialize()
            if standalone and self.inst.state == LifecycleState.INACTIVE:
                await self.inst.runner.activate()
        except Exception as exc:
            log.error("start failed: %s", exc)

    def _on_command(self, request: Request | Refusal) -> None:
        """The channel decoded a command (or one it cannot read): queue it; but `exit` is
        carried out at once, even while another command runs (the agent sends it when that one
        timed out, e.g. a `deactivate` waiting for a component blocked in `send()`): that one
        is abandoned and answered `ok: false`, like those still queued."""
        if (
            isinstance(request, Request)
            and isinstance(request.command, Exit)
            and self.exit_request is None
        ):
            self.exit_request = (request.id, request.command)
            self.stop.set()
            return
        self._queue.put_nowait(request)

    def _on_closed(self, reason: str) -> None:
        """The control channel ended: a host never outlives its agent."""
        if not self.stop.is_set():
            log.warning("%s: finalizing and exiting", reason)
            self.stop.set()

    def _counters(self) -> dict[str, dict[str, int]]:
        """Per-port counters for heartbeats (empty before the instance exists). An InPort's
        `bytes_in` is what the data server received for it: the frames' encoded bytes, for
        values of any type."""
        inst: HostedInstance | None = getattr(self, "inst", None)
        if inst is None:
            return {}
        counters = inst.counters()
        server = self._server
        if server is not None:
            for port, n in server.bytes_in.items():
                if port in counters and port in inst.in_ports:
                    counters[port]["bytes_in"] = n
        return counters

    def _data_counters(self) -> dict[str, int]:
        """The data server's counters for heartbeats (docs/protocol.md)."""
        return {} if self._server is None else dict(self._server.counters)

    async def _serve_commands(self) -> None:
        """Run queued commands in order, answering each one."""
        assert self.channel is not None
        while True:
            request = await self._queue.get()
            if isinstance(request, Refusal):
                log.warning("%s (id %d) refused: %s", request.t, request.id, request.error)
                self.channel.send(Reply(request.id, False, request.error))
                continue
            if isinstance(request.command, Exit):  # a second exit: answered on the way out
                self._queue.put_nowait(request)
                return
            self._running = request
            try:
                blob = await self.inst.execute(request)
            except Exception as exc:
                log.warning("%s (id %d) failed: %s", request.command.T, request.id, exc)
                self.channel.send(Reply(request.id, False, str(exc) or repr(exc)))
            else:
                if blob is None:
                    self.channel.send(Reply(request.id, True))
                else:
                    done = Reply(request.id, True, size=len(blob))
                    self.channel.send(done, *parts(request.id, blob))
            self._running = None  # (a command cancelled for the exit stays: _goodbye answers it)

    def _exit_timeout(self) -> float:
        """Seconds finalizing may take: the `exit` command's timeout, else the default."""
        if self.exit_request is not None:
            timeout = self.exit_request[1].timeout
            if timeout is not None and timeout > 0:
                return timeout
        return FINALIZE_TIMEOUT

    async def _finalize(self, runner: ComponentRunner) -> int:
        """Finalize the runner within the timeout; 0 if it did, 1 otherwise."""
        if self.inst.state == LifecycleState.FINALIZED:
            return 0
        try:
            async with asyncio.timeout(self._exit_timeout()):  # not wait_for (see below)
                await runner.finalize()
        except TimeoutError:
            log.error("finalize did not finish within %.1f s", self._exit_timeout())
            self._error = "finalize timed out"
            return 1
        except Exception as exc:
            log.error("finalize failed: %s", exc)
            self._error = str(exc)
            return 1
        return 0

    async def _goodbye(self, code: int) -> None:
        """Answer `exit` and close the channel once the last report is written."""
        if self.channel is None:
            return
        if self._running is not None:  # abandoned for the exit
            self.channel.send(Reply(self._running.id, False, "the host is exiting"))
            self._running = None
        if self.exit_request is not None:
            error = None if code == 0 else self._error
            self.channel.send(Reply(self.exit_request[0], code == 0, error))
        while not self._queue.empty():  # every command gets exactly one reply
            late = self._queue.get_nowait()
            self.channel.send(Reply(late.id, False, "the host is exiting"))
        self.channel.close()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(1.0):  # wait_for can swallow a cancel on 3.11
                await self.channel.wait_closed()

    def _unix_path(self) -> str:
        """Where the Unix data socket goes."""
        run_dir = self.config.run_dir
        if run_dir is None:
            import tempfile  # noqa: PLC0415 - standalone only; keeps the agent's hosts lighter

            run_dir = self.tmp_dir = tempfile.mkdtemp(prefix="sdrpeer-host-")
        safe = re.sub(r"[^A-Za-z0-9_.-]", "_", self.name)[:40] or "host"
        return os.path.join(run_dir, f"{safe}.sock")

    async def _log_counters(self) -> None:
        """Standalone: port counters once a second."""
        while True:
            await asyncio.sleep(STANDALONE_REPORT_INTERVAL)
            log.info("ports %s", _compact(self.inst.counters()))


def _no_report(report: Report) -> None:
    """Standalone: nobody to report to (the instance and the component log what matters)."""


def _compact(counters: dict[str, dict[str, Any]]) -> str:
    """`out: frames_out=10 bytes_out=80; ...` with zero counters left out."""
    parts = []
    for port, values in sorted(counters.items()):
        shown = " ".join(f"{k}={v}" for k, v in values.items() if v)
        parts.append(f"{port}: {shown or '-'}")
    return "; ".join(parts) or "(no ports)"


def install_signals(loop: asyncio.AbstractEventLoop, stop: asyncio.Event) -> None:
    """SIGTERM/SIGINT ask for a clean exit; a second one forces it (signal handlers only queue)."""

    def on_signal(signum: int) -> None:
        if stop.is_set():
            log.warning("second %s: exiting now", signal.Signals(signum).name)
            os._exit(1)
        log.info("%s: finalizing", signal.Signals(signum).name)
        stop.set()

    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, on_signal, sig)


def now() -> float:
    """Unix seconds, for reports."""
    return time.time()
